"""Codecs of every bus message: Python values <-> protobuf bytes (schemas in proto/messages.proto).

``encode_*`` take numpy arrays and plain numbers and raise ValueError on bad arguments;
``decode_*`` take untrusted bytes and raise ``BadMessage`` with a reason, never anything else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from google.protobuf.message import DecodeError, Message

from layerpilot.bus import arrays
from layerpilot.bus.keys import check_vehicle
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage
from layerpilot.grid import GridGeometry

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
    out = np.array([v.x, v.y, v.z], np.float64)
    arrays.require_finite(out, name)
    return out


def _set_vec(v: pb.Vec3, xyz: np.ndarray | tuple[float, float, float]) -> None:
    v.x, v.y, v.z = (float(c) for c in np.asarray(xyz, np.float64).reshape(3))


def _quat(q: pb.Quaternion, name: str) -> np.ndarray:
    out = np.array([q.w, q.x, q.y, q.z], np.float64)
    arrays.require_finite(out, name)
    with np.errstate(over="ignore"):
        norm = float(np.linalg.norm(out))
    if abs(norm - 1.0) > 1e-3:
        raise BadMessage("bad quaternion", f"{name}: norm {norm:.4g}, expected 1")
    return out


def _set_quat(q: pb.Quaternion, wxyz: np.ndarray | tuple[float, ...]) -> None:
    q.w, q.x, q.y, q.z = (float(c) for c in np.asarray(wxyz, np.float64).reshape(4))


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a 3x3 rotation matrix (Shepperd's method, w >= 0)."""
    R = np.asarray(R, np.float64)
    t = np.trace(R)
    if t > 0:
        s = 2.0 * math.sqrt(t + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + R[i, i] - R[j, j] - R[k, k], 1e-300))
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q = np.array(q)
    return q if q[0] >= 0 else -q


def matrix_from_quat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


# --- point clouds ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Cloud:
    stamp: float
    vehicle: str
    seq: int
    points: np.ndarray  # (n, 3) float32
    origin: np.ndarray  # (3,) float64
    colors: np.ndarray | None = None  # (n, 3) uint8
    max_range: float = 0.0


def encode_cloud(c: Cloud) -> bytes:
    m = pb.PointCloud(stamp=float(c.stamp), vehicle=check_vehicle(c.vehicle), seq=int(c.seq),
                      max_range=float(c.max_range))
    pts = np.asarray(c.points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points: expected shape (N, 3), got {pts.shape}")
    arrays.to_proto(pts.astype(np.float32, copy=False), m.points)
    if c.colors is not None:
        cols = np.asarray(c.colors)
        if cols.shape != pts.shape or cols.dtype != np.uint8:
            raise ValueError(f"colors: expected {pts.shape} uint8, got {cols.shape} {cols.dtype}")
        arrays.to_proto(cols, m.colors)
    _set_vec(m.origin, c.origin)
    return m.SerializeToString()


def decode_cloud(payload: bytes) -> Cloud:
    m = parse(pb.PointCloud, payload)
    if not m.HasField("points"):
        raise BadMessage("missing field", "points")
    points = arrays.require_finite(arrays.from_proto(m.points, "points", dtype="float32", shape=(None, 3)), "points")
    colors = None
    if m.HasField("colors"):
        colors = arrays.from_proto(m.colors, "colors", dtype="uint8", shape=(len(points), 3))
    max_range = _finite(m.max_range, "max_range")
    if max_range < 0:
        raise BadMessage("out of range", f"max_range: {max_range} < 0")
    return Cloud(_finite(m.stamp, "stamp"), _vehicle(m), m.seq, points, _vec(m.origin, "origin"), colors, max_range)


# --- camera frames --------------------------------------------------------------------------

@dataclass(frozen=True)
class Frame:
    stamp: float
    vehicle: str
    seq: int
    image: np.ndarray  # (h, w, 3) uint8 RGB
    intrinsics: tuple[float, float, float, float]  # fx, fy, cx, cy (pixels)
    position: np.ndarray  # (3,) camera centre, map frame
    orientation: np.ndarray  # (4,) w, x, y, z: camera -> map
    depth: np.ndarray | None = None  # (h, w) float32 metres


def encode_frame(f: Frame) -> bytes:
    img = np.asarray(f.image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image: expected (h, w, 3) uint8, got {img.shape} {img.dtype}")
    m = pb.CameraFrame(stamp=float(f.stamp), vehicle=check_vehicle(f.vehicle), seq=int(f.seq))
    arrays.to_proto(img, m.image)
    if f.depth is not None:
        d = np.asarray(f.depth, np.float32)
        if d.shape != img.shape[:2]:
            raise ValueError(f"depth: expected shape {img.shape[:2]}, got {d.shape}")
        arrays.to_proto(d, m.depth)
    fx, fy, cx, cy = (float(v) for v in f.intrinsics)
    m.intrinsics.CopyFrom(pb.Intrinsics(fx=fx, fy=fy, cx=cx, cy=cy, width=img.shape[1], height=img.shape[0]))
    _set_vec(m.pose.position, f.position)
    _set_quat(m.pose.orientation, f.orientation)
    return m.SerializeToString()


def decode_frame(payload: bytes) -> Frame:
    m = parse(pb.CameraFrame, payload)
    if not m.HasField("image"):
        raise BadMessage("missing field", "image")
    k = m.intrinsics
    image = arrays.from_proto(m.image, "image", dtype="uint8", shape=(k.height, k.width, 3))
    depth = None
    if m.HasField("depth"):
        # NaN / +inf depth means "no measurement" (sky); negative depth is impossible
        depth = arrays.from_proto(m.depth, "depth", dtype="float32", shape=(k.height, k.width))
        if np.any(depth < 0):
            raise BadMessage("out of range", "depth: negative values")
    intr = np.array([k.fx, k.fy, k.cx, k.cy])
    arrays.require_finite(intr, "intrinsics")
    if not (k.fx > 0 and k.fy > 0):
        raise BadMessage("out of range", f"intrinsics: focal lengths must be > 0, got {k.fx}, {k.fy}")
    return Frame(_finite(m.stamp, "stamp"), _vehicle(m), m.seq, image, tuple(float(v) for v in intr),
                 _vec(m.pose.position, "pose.position"), _quat(m.pose.orientation, "pose.orientation"), depth)


# --- vehicle state --------------------------------------------------------------------------

@dataclass(frozen=True)
class State:
    stamp: float
    vehicle: str
    position: np.ndarray  # (3,) map frame
    orientation: np.ndarray = field(default_factory=lambda: np.array([1.0, 0, 0, 0]))  # w, x, y, z body -> map
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    armed: bool = False
    mode: str = ""
    battery: float = math.nan


def encode_state(s: State) -> bytes:
    m = pb.VehicleState(stamp=float(s.stamp), vehicle=check_vehicle(s.vehicle), armed=bool(s.armed),
                        mode=str(s.mode), battery=float(s.battery))
    _set_vec(m.pose.position, s.position)
    _set_quat(m.pose.orientation, s.orientation)
    _set_vec(m.velocity, s.velocity)
    return m.SerializeToString()


def decode_state(payload: bytes) -> State:
    m = parse(pb.VehicleState, payload)
    if not m.HasField("pose"):
        raise BadMessage("missing field", "pose")
    battery = m.battery
    if not (math.isnan(battery) or 0.0 <= battery <= 1.0):
        raise BadMessage("out of range", f"battery: {battery} not in [0, 1]")
    return State(_finite(m.stamp, "stamp"), _vehicle(m), _vec(m.pose.position, "pose.position"),
                 _quat(m.pose.orientation, "pose.orientation"), _vec(m.velocity, "velocity"), m.armed, m.mode, battery)


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


def encode_decision(d: Decision) -> bytes:
    m = pb.Decision(stamp=float(d.stamp), vehicle=check_vehicle(d.vehicle), seq=int(d.seq), score=float(d.score),
                    behavior=str(d.behavior))
    _set_vec(m.waypoint, d.waypoint)
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
    return Decision(_finite(m.stamp, "stamp"), _vehicle(m), m.seq, _vec(m.waypoint, "waypoint"),
                    _finite(m.score, "score"), tuple(terms), m.behavior)


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
