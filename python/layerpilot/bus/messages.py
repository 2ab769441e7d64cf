"""Codecs of every bus message: Python values <-> protobuf bytes (schemas in proto/messages.proto).

``encode_*`` take a message value and raise ValueError on bad arguments; ``decode_*`` take
untrusted bytes and raise ``BadMessage`` with a reason, never anything else. Camera frames,
point clouds and poses are the ground-floor types of ``layerpilot.geometry``; a ``*Message``
adds the envelope the bus needs (vehicle, sequence number, ...).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np
from google.protobuf.message import DecodeError, Message

from layerpilot.bus import arrays, limits
from layerpilot.bus.keys import NODES, check_vehicle
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage
from layerpilot.geometry import CameraFrame, CameraIntrinsics, PointCloud, Pose

MAX_PAYLOAD = 64 << 20


def parse(cls: type[Message], payload: bytes | bytearray | memoryview) -> Message:
    """Parse untrusted bytes into ``cls``; BadMessage on anything that is not one."""
    data = bytes(payload)
    if len(data) > MAX_PAYLOAD:
        raise BadMessage("too large", f"{len(data)} bytes is more than {MAX_PAYLOAD}")
    msg = cls()
    try:
        msg.ParseFromString(data)
    except (DecodeError, RuntimeError, ValueError) as exc:
        raise BadMessage("not protobuf", f"not a {cls.DESCRIPTOR.name}: {exc}") from None
    return msg


def _vehicle(msg: Message) -> str:
    try:
        return check_vehicle(msg.vehicle)
    except ValueError as exc:
        raise BadMessage("bad vehicle", str(exc)) from None


def _finite(value: float, name: str) -> float:
    if not math.isfinite(value):
        raise BadMessage("not finite", f"{name}: {value}")
    return value


def _vec(v: pb.Vec3, name: str) -> np.ndarray:
    """A finite 3-vector within ±MAX_COORDINATE (the map frame is local: 1e300 m is an attack, not a place)."""
    out = np.array([v.x, v.y, v.z], np.float64)
    arrays.require_finite(out, name)
    if np.any(np.abs(out) > limits.MAX_COORDINATE):
        raise BadMessage("out of range", f"{name}: {out.tolist()} is not within ±{limits.MAX_COORDINATE:g}")
    return out


def _set_vec(v: pb.Vec3, xyz: np.ndarray | tuple[float, float, float]) -> None:
    v.x, v.y, v.z = (float(c) for c in np.asarray(xyz, np.float64).reshape(3))


def _set_pose(m: pb.Pose, pose: Pose) -> None:
    if not isinstance(pose, Pose):
        raise ValueError(f"pose: expected a layerpilot.geometry.Pose, got {type(pose).__name__}")
    _set_vec(m.position, pose.position)
    m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z = (float(c) for c in pose.orientation)


def _pose(m: pb.Pose, name: str) -> Pose:
    q = np.array([m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z], np.float64)
    arrays.require_finite(q, f"{name}.orientation")
    try:
        return Pose(_vec(m.position, f"{name}.position"), q)
    except ValueError as exc:
        raise BadMessage("bad pose", f"{name}.{exc}") from None


# --- point clouds ---------------------------------------------------------------------------

@dataclass(frozen=True)
class CloudMessage:
    """``layerpilot/<vehicle>/cloud``: a map-frame point cloud from ``vehicle``'s depth source."""

    vehicle: str
    seq: int
    cloud: PointCloud
    max_range: float = 0.0  # metres the sender trusts its rays to: it only lowers the map server's; 0 = the server's


def encode_cloud(c: CloudMessage) -> bytes:
    cloud = c.cloud
    if not isinstance(cloud, PointCloud):
        raise ValueError(f"cloud: expected a layerpilot.geometry.PointCloud, got {type(cloud).__name__}")
    m = pb.PointCloud(stamp=cloud.stamp, vehicle=check_vehicle(c.vehicle), seq=int(c.seq),
                      max_range=float(c.max_range))
    arrays.to_proto(cloud.points, m.points)
    if cloud.colors is not None:
        arrays.to_proto(cloud.colors, m.colors)
    _set_vec(m.origin, cloud.origin)
    return m.SerializeToString()


def decode_cloud(payload: bytes) -> CloudMessage:
    m = parse(pb.PointCloud, payload)
    if not m.HasField("points"):
        raise BadMessage("missing field", "points")
    points = arrays.require_finite(arrays.from_proto(m.points, "points", dtype="float32", shape=(None, 3),
                                                     max_items=3 * limits.MAX_CLOUD_POINTS), "points")
    colors = None
    if m.HasField("colors"):
        colors = arrays.from_proto(m.colors, "colors", dtype="uint8", shape=(len(points), 3))
    max_range = _finite(m.max_range, "max_range")
    if max_range < 0:
        raise BadMessage("out of range", f"max_range: {max_range} < 0")
    cloud = PointCloud(points, _vec(m.origin, "origin"), _finite(m.stamp, "stamp"), colors)
    return CloudMessage(_vehicle(m), m.seq, cloud, max_range)


# --- camera frames --------------------------------------------------------------------------

@dataclass(frozen=True)
class FrameMessage:
    """``layerpilot/<vehicle>/camera``: one camera frame (pose in the map frame) from ``vehicle``."""

    vehicle: str
    seq: int
    frame: CameraFrame


def encode_frame(f: FrameMessage) -> bytes:
    frame = f.frame
    if not isinstance(frame, CameraFrame):
        raise ValueError(f"frame: expected a layerpilot.geometry.CameraFrame, got {type(frame).__name__}")
    m = pb.CameraFrame(stamp=frame.stamp, vehicle=check_vehicle(f.vehicle), seq=int(f.seq))
    arrays.to_proto(frame.image, m.image)
    if frame.depth is not None:
        arrays.to_proto(frame.depth, m.depth)
    k = frame.intrinsics
    m.intrinsics.CopyFrom(pb.Intrinsics(fx=k.fx, fy=k.fy, cx=k.cx, cy=k.cy, width=k.width, height=k.height))
    _set_pose(m.pose, frame.pose)
    return m.SerializeToString()


def decode_frame(payload: bytes) -> FrameMessage:
    m = parse(pb.CameraFrame, payload)
    if not m.HasField("image"):
        raise BadMessage("missing field", "image")
    k = m.intrinsics
    if k.width * k.height > limits.MAX_FRAME_PIXELS:
        raise BadMessage("too large", f"image: {k.width}x{k.height} is more than {limits.MAX_FRAME_PIXELS} pixels")
    image = arrays.from_proto(m.image, "image", dtype="uint8", shape=(k.height, k.width, 3))
    depth = None
    if m.HasField("depth"):
        # NaN / +inf depth means "no measurement" (sky); negative depth is impossible
        depth = arrays.from_proto(m.depth, "depth", dtype="float32", shape=(k.height, k.width))
        if np.any(depth < 0):
            raise BadMessage("out of range", "depth: negative values")
    arrays.require_finite(np.array([k.fx, k.fy, k.cx, k.cy]), "intrinsics")
    try:
        intrinsics = CameraIntrinsics(k.fx, k.fy, k.cx, k.cy, k.width, k.height)
    except ValueError as exc:
        raise BadMessage("out of range", f"intrinsics: {exc}") from None
    frame = CameraFrame(image, _pose(m.pose, "pose"), intrinsics, _finite(m.stamp, "stamp"), depth)
    return FrameMessage(_vehicle(m), m.seq, frame)


# --- vehicle state --------------------------------------------------------------------------

@dataclass(frozen=True)
class State:
    """``layerpilot/<vehicle>/pose``: the vehicle's pose (body FLU -> map) and what its autopilot reports."""

    stamp: float
    vehicle: str
    pose: Pose
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,) map frame m/s
    armed: bool = False
    mode: str = ""
    battery: float = math.nan

    @property
    def position(self) -> np.ndarray:
        """The vehicle's position in the map frame (``pose.position``)."""
        return self.pose.position


def encode_state(s: State) -> bytes:
    m = pb.VehicleState(stamp=float(s.stamp), vehicle=check_vehicle(s.vehicle), armed=bool(s.armed),
                        mode=str(s.mode), battery=float(s.battery))
    _set_pose(m.pose, s.pose)
    _set_vec(m.velocity, s.velocity)
    return m.SerializeToString()


def decode_state(payload: bytes) -> State:
    m = parse(pb.VehicleState, payload)
    if not m.HasField("pose"):
        raise BadMessage("missing field", "pose")
    battery = m.battery
    if not (math.isnan(battery) or 0.0 <= battery <= 1.0):
        raise BadMessage("out of range", f"battery: {battery} not in [0, 1]")
    return State(_finite(m.stamp, "stamp"), _vehicle(m), _pose(m.pose, "pose"), _vec(m.velocity, "velocity"),
                 m.armed, m.mode, battery)


# --- waypoints and decisions ----------------------------------------------------------------

@dataclass(frozen=True)
class Waypoint:
    stamp: float
    vehicle: str
    seq: int
    position: np.ndarray  # (3,) map frame
    yaw: float = math.nan  # radians ENU, NaN = keep heading
    speed: float = 0.0  # m/s, 0 = autopilot default


def encode_waypoint(w: Waypoint) -> bytes:
    m = pb.Waypoint(stamp=float(w.stamp), vehicle=check_vehicle(w.vehicle), seq=int(w.seq),
                    yaw=float(w.yaw), speed=float(w.speed))
    _set_vec(m.position, w.position)
    return m.SerializeToString()


def decode_waypoint(payload: bytes) -> Waypoint:
    m = parse(pb.Waypoint, payload)
    if not m.HasField("position"):
        raise BadMessage("missing field", "position")
    if math.isinf(m.yaw):
        raise BadMessage("not finite", "yaw: inf")
    if not (math.isfinite(m.speed) and m.speed >= 0):
        raise BadMessage("out of range", f"speed: {m.speed}")
    return Waypoint(_finite(m.stamp, "stamp"), _vehicle(m), m.seq, _vec(m.position, "position"), m.yaw, m.speed)


@dataclass(frozen=True)
class Term:
    name: str
    weight: float
    value: float
    contribution: float


@dataclass(frozen=True)
class Decision:
    stamp: float
    vehicle: str
    seq: int
    waypoint: np.ndarray  # (3,)
    score: float
    terms: tuple[Term, ...]
    behavior: str = ""
    runner_up: np.ndarray | None = None  # (3,) the second-best choice, if any
    explanation: str = ""  # one line a person can read


def encode_decision(d: Decision) -> bytes:
    m = pb.Decision(stamp=float(d.stamp), vehicle=check_vehicle(d.vehicle), seq=int(d.seq), score=float(d.score),
                    behavior=str(d.behavior), explanation=str(d.explanation))
    _set_vec(m.waypoint, d.waypoint)
    if d.runner_up is not None:
        _set_vec(m.runner_up, d.runner_up)
    for t in d.terms:
        m.terms.add(name=t.name, weight=float(t.weight), value=float(t.value), contribution=float(t.contribution))
    return m.SerializeToString()


def decode_decision(payload: bytes) -> Decision:
    m = parse(pb.Decision, payload)
    terms = []
    for i, t in enumerate(m.terms):
        for attr in ("weight", "value", "contribution"):
            _finite(getattr(t, attr), f"terms[{i}].{attr}")
        terms.append(Term(t.name, t.weight, t.value, t.contribution))
    runner_up = _vec(m.runner_up, "runner_up") if m.HasField("runner_up") else None
    return Decision(_finite(m.stamp, "stamp"), _vehicle(m), m.seq, _vec(m.waypoint, "waypoint"),
                    _finite(m.score, "score"), tuple(terms), m.behavior, runner_up, m.explanation)


# --- mission state --------------------------------------------------------------------------

@dataclass(frozen=True)
class MissionState:
    stamp: float
    vehicle: str
    phase: str
    waypoints_sent: int = 0
    waypoints_reached: int = 0
    distance_flown: float = 0.0
    target: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # NaN = none


def encode_mission_state(s: MissionState) -> bytes:
    m = pb.MissionState(stamp=float(s.stamp), vehicle=check_vehicle(s.vehicle), phase=s.phase,
                        waypoints_sent=int(s.waypoints_sent), waypoints_reached=int(s.waypoints_reached),
                        distance_flown=float(s.distance_flown))
    _set_vec(m.target, s.target)
    return m.SerializeToString()


def decode_mission_state(payload: bytes) -> MissionState:
    m = parse(pb.MissionState, payload)
    target = np.array([m.target.x, m.target.y, m.target.z])
    if np.any(np.isinf(target)):
        raise BadMessage("not finite", "target: inf")
    return MissionState(_finite(m.stamp, "stamp"), _vehicle(m), m.phase, m.waypoints_sent, m.waypoints_reached,
                        _finite(m.distance_flown, "distance_flown"), target)


# --- node health ----------------------------------------------------------------------------

MAX_HEALTH_BYTES = 64 << 10  # a status line is a few hundred bytes; more is not a status line


@dataclass(frozen=True)
class NodeHealth:
    """A node's status line on the bus: the same dict its JSON status line prints, for the view and recordings."""

    vehicle: str
    node: str  # keys.NODES
    uptime: float  # s since the node started (monotonic): counter differences over it are rates
    status: dict


def encode_health(h: NodeHealth) -> bytes:
    if h.node not in NODES:
        raise ValueError(f"health: unknown node {h.node!r}; known: {', '.join(NODES)}")
    return pb.NodeHealth(vehicle=check_vehicle(h.vehicle), node=h.node, uptime=float(h.uptime),
                         status=json.dumps(h.status, allow_nan=False)).SerializeToString()


def decode_health(payload: bytes) -> NodeHealth:
    m = parse(pb.NodeHealth, payload)
    if m.node not in NODES:
        raise BadMessage("unknown node", f"node: {m.node!r} is not one of {', '.join(NODES)}")
    if len(m.status) > MAX_HEALTH_BYTES:
        raise BadMessage("too large", f"status: {len(m.status)} characters is more than {MAX_HEALTH_BYTES}")
    try:
        status = json.loads(m.status)
    except ValueError as exc:
        raise BadMessage("bad status", f"status: not JSON ({exc})") from None
    if not isinstance(status, dict):
        raise BadMessage("bad status", f"status: a JSON object expected, got {type(status).__name__}")
    return NodeHealth(_vehicle(m), m.node, _finite(m.uptime, "uptime"), status)
