"""`layerpilot view`: join a running mission on the bus and log what it says into a MissionScene.

Zenoh callbacks only decode and keep the newest message per key (and count arrivals, for the
rates); one worker logs them every ``period`` seconds, the path and the map server's voxels and
statistics every ``map_period`` seconds, and turns each layer set into layer images and metrics.
On the same period it asks the decide node for the last tick's aggregate layers A0..A3 (a
queryable: the decide node sends them to no one else) and plots each node's health
(``health/<node>``: the counters of its status line, their rates, heartbeat and input ages).
In a fleet the view also follows the other drones: each one's position and current target
(their ``pose`` and ``decision``), drawn beside the followed drone's.
A bad message is rejected and counted like in any node; the view never publishes anything.
When nothing at all came in the first SILENCE seconds, it says so once (``warn``, and the
scene's ``log``): a view on the wrong endpoint or vehicle, or with no mission, looks like a
quiet one otherwise.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable

import numpy as np
import zenoh

from layerpilot.bus import arrays, keys
from layerpilot.bus import messages as msg
from layerpilot.bus.layerset import decode_layer_set, to_column_layers
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.decide import zone_mask
from layerpilot.grid import GridGeometry
from layerpilot.map.columns import ColumnLayers
from layerpilot.map.voxel_map import Voxels
from layerpilot.missionfile import Mission
from layerpilot.nodes.decide import decode_aggregates
from layerpilot.viz.scene import MissionScene, area_outline

_log = logging.getLogger("layerpilot.view")
DECODERS = {"camera": msg.decode_frame, "pose": msg.decode_state, "layers": decode_layer_set,
            "decision": msg.decode_decision, "waypoint": msg.decode_waypoint, "state": msg.decode_mission_state}
FLEET_TOPICS = {"pose": msg.decode_state, "decision": msg.decode_decision}  # what the view hears of the other drones
# no clouds: they are the map server's, the view shows its map (and a cloud crossing a ground link costs MBs)
VOXEL_BOX = 500  # voxels per side of the box the view asks the map server for
SILENCE = 5.0  # s without a single message before the view says it hears nothing
Metrics = Callable[[ColumnLayers, np.ndarray, float], dict[str, float]]


class LiveView:
    """The scene of one vehicle of a running mission (``metrics``: layers, area mask, now -> named values)."""

    def __init__(self, session: zenoh.Session, mission: Mission, scene: MissionScene, vehicle: str | None = None,
                 metrics: Metrics | None = None, period: float = 0.2, map_period: float = 2.0,
                 warn: Callable[[str], None] = _log.warning) -> None:
        """``warn``: where the one line goes when the bus stays silent (the view command: its console)."""
        self.session, self.mission, self.scene, self.metrics, self.warn = session, mission, scene, metrics, warn
        self.vehicle = vehicle or mission.vehicles[0]
        self.keys = keys.Keys(self.vehicle)
        self.period, self.map_period = period, map_period
        self.behavior = mission.decide.flown_behavior()
        self.rejects = Rejects(_log)
        self.heard: Counter[str] = Counter()  # messages per topic of this vehicle
        self.logged: Counter[str] = Counter()  # what went into the scene, per kind
        self._newest: dict[str, object] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._any = threading.Event()  # a message arrived on a subscribed key (good or rejected)
        self._now = 0.0  # newest mission time heard
        self._aoi: tuple[object, np.ndarray] | None = None
        self._grid: GridGeometry | None = None  # the layer images' grid: the aggregates are placed on it
        self._aggregates: tuple[float, GridGeometry] | None = None  # the last logged tick
        self._health: dict[str, tuple[float, dict]] = {}  # node -> (uptime, status) last logged
        self._subs: list = []
        self._thread = threading.Thread(target=self._run, name="view", daemon=True)

    def start(self) -> None:
        self.scene.area(area_outline(self.behavior.area.shape, self.behavior.area.radius,
                                     self.behavior.area.center or self.mission.decide.home,
                                     self.behavior.area.polygon))
        self._subs = [self.session.declare_subscriber(self.keys.topic(topic), self._on_sample) for topic in DECODERS]
        self._subs.append(self.session.declare_subscriber(f"{keys.PREFIX}/{self.vehicle}/health/*", self._on_health))
        for other in self.mission.vehicles:
            if other != self.vehicle:
                self._subs += [self.session.declare_subscriber(keys.Keys(other).topic(t), self._on_fleet)
                               for t in FLEET_TOPICS]
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        for sub in self._subs:
            sub.undeclare()
        self._thread.join()

    def _on_health(self, sample: zenoh.Sample) -> None:
        self._any.set()
        key = str(sample.key_expr)
        try:
            health = msg.decode_health(sample.payload.to_bytes())
            if key != self.keys.health(health.node) or health.vehicle != self.vehicle:
                raise BadMessage("wrong key", f"health of {health.node} of {health.vehicle} on {key}")
        except BadMessage as exc:
            self.rejects.reject(key, exc)
            return
        with self._lock:
            self.heard["health"] += 1
            self._newest.setdefault("health", []).append(health)

    def _on_fleet(self, sample: zenoh.Sample) -> None:
        """Another drone's pose or decision: its newest position or target, checked against its key."""
        self._any.set()
        key = str(sample.key_expr)
        name, topic = keys.vehicle_of(key), key.rsplit("/", 1)[-1]
        try:
            message = FLEET_TOPICS[topic](sample.payload.to_bytes())
            if message.vehicle != name:
                raise BadMessage("wrong key", f"{topic} of {message.vehicle} on {key}")
        except BadMessage as exc:
            self.rejects.reject(key, exc)
            return
        with self._lock:
            self.heard[f"fleet/{topic}"] += 1
            self._newest.setdefault("fleet", {}).setdefault(name, {})[topic] = message

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self._any.set()
        key = str(sample.key_expr)
        topic = key.rsplit("/", 1)[-1]
        try:
            message = DECODERS[topic](sample.payload.to_bytes())
        except BadMessage as exc:
            self.rejects.reject(key, exc)
            return
        with self._lock:
            self.heard[topic] += 1
            self._newest[topic] = message
            if topic == "pose":  # every pose: the path is drawn from all of them
                self._newest.setdefault("poses", []).append(message)

    def _run(self) -> None:
        next_map, last_rates, last_counts = 0.0, time.monotonic(), Counter()
        silence_check: float | None = time.monotonic() + SILENCE  # nothing heard by then: say so, once
        while not self._stop.wait(self.period):
            with self._lock:
                newest, self._newest = self._newest, {}
                counts = self.heard.copy()
            try:
                now = time.monotonic()
                if silence_check is not None and now >= silence_check:
                    silence_check = None
                    if not self._any.is_set():
                        self._say_silent()
                self._log_messages(newest)
                if now >= next_map:
                    next_map = now + self.map_period
                    self.scene.path()
                    self._log_map()
                    self._log_aggregates()
                    rates = {f"rate/{t}": (counts[t] - last_counts[t]) / (now - last_rates) for t in counts}
                    self.scene.scalars("health", {**rates, "view/rejected": self.rejects.total})
                    last_rates, last_counts = now, counts
            except Exception as exc:  # the view keeps going; the first failure of a kind is logged
                self.rejects.reject("view", BadMessage(f"logging failed ({type(exc).__name__})", str(exc)))

    def _say_silent(self) -> None:
        line = (f"heard nothing on {keys.PREFIX}/{self.vehicle}/** for {SILENCE:g} s: is a mission with vehicle "
                f"{self.vehicle} running (layerpilot up), and are --endpoint and --credentials right?")
        self.warn(line)
        self.scene.at(self._now)
        self.scene.text(line, "WARN")

    def _log_messages(self, newest: dict) -> None:
        for state in newest.get("poses", []):
            self._now = max(self._now, state.stamp)
            self.scene.at(state.stamp)
            self.scene.pose(state.pose)
            self.logged["pose"] += 1
        if (frame := newest.get("camera")) is not None:
            self.scene.at(frame.frame.stamp)
            self.scene.camera(frame.frame)
            self.logged["camera"] += 1
        if (d := newest.get("decision")) is not None:
            self.scene.at(d.stamp)
            self.scene.decision(d.waypoint, d.runner_up, d.explanation or f"{d.behavior} waypoint {d.seq}: "
                                f"({d.waypoint[0]:.1f}, {d.waypoint[1]:.1f}, {d.waypoint[2]:.1f}) score {d.score:.4f}")
            self.logged["decision"] += 1
        if (ls := newest.get("layers")) is not None:
            columns = to_column_layers(ls)
            self._grid = columns.geometry
            self.scene.at(max(self._now, ls.stamp))
            self.scene.layers({"color": columns.color, "elevation": np.where(columns.observed, columns.elevation,
                                                                             np.nan),
                               "time_since_seen": np.where(columns.observed, self._now - columns.last_seen, np.nan),
                               "distance": np.where(columns.observed, columns.min_distance, np.nan)},
                              columns.geometry)
            if self.metrics is not None:
                self.scene.scalars("metrics", self.metrics(columns, self._area(columns), max(self._now, ls.stamp)))
            self.logged["layers"] += 1
        for name, heard in newest.get("fleet", {}).items():
            pose, decision = heard.get("pose"), heard.get("decision")
            self.scene.at(max(m.stamp for m in heard.values()))  # on the other drone's own clock
            self.scene.fleet_member(name, None if pose is None else pose.pose.position,
                                    None if decision is None else decision.waypoint)
            self.logged[f"fleet/{name}"] += 1
        for health in newest.get("health", []):  # no mission stamp of their own: logged at the newest one heard
            self.scene.at(self._now)
            self.scene.scalars(f"health/{health.node}", self._health_series(health))
            self.logged[f"health/{health.node}"] += 1

    def _health_series(self, h: msg.NodeHealth) -> dict[str, float]:
        """A node's status as time series: its numbers (a nested count like ``inputs`` per key's last part),
        and per second how each whole-number counter grew since the node's previous status."""
        values: dict[str, float] = {}
        for name, value in h.status.items():
            items = value.items() if isinstance(value, dict) else [("", value)]
            for sub, v in items:
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    values[f"{name}/{str(sub).rsplit('/', 1)[-1]}" if sub else name] = float(v)
        before = self._health.get(h.node)
        self._health[h.node] = (h.uptime, h.status)
        if before is not None and h.uptime > before[0]:
            for name, v in h.status.items():
                old = before[1].get(name)
                if isinstance(v, int) and isinstance(old, int) and not isinstance(v, bool):
                    values[f"rate/{name}"] = (v - old) / (h.uptime - before[0])
        return values

    def _log_aggregates(self) -> None:
        """The decide node's last tick, A0..A3 over the layer images, if it is a new one."""
        if self._grid is None or (reply := self._query(self.keys.aggregates, "", quiet=True)) is None:
            return
        try:
            ls = decode_aggregates(reply, self.vehicle)
        except BadMessage as exc:
            self.rejects.reject(self.keys.aggregates, exc)
            return
        if self._aggregates == (ls.stamp, ls.geometry):
            return
        self._aggregates = (ls.stamp, ls.geometry)
        self.scene.at(ls.stamp)
        self.scene.aggregates(ls.layers, ls.geometry, self._grid)
        self.logged["aggregates"] += 1

    def _area(self, columns: ColumnLayers) -> np.ndarray:
        if self._aoi is None or self._aoi[0] != columns.geometry:
            mask = zone_mask(self.behavior.area, columns.geometry, self.mission.decide.home) > 0.5
            self._aoi = (columns.geometry, mask)
        return self._aoi[1]

    def _log_map(self) -> None:
        """The map server's occupied voxels in its layer window (paged) and its statistics."""
        x, y, w, h = self.mission.map_server.window
        res = self.mission.map_server.resolution
        span = VOXEL_BOX * res  # the map service answers boxes of at most MAX_BOX voxels a side
        lo, hi = (x, y, -0.2 * span), (x + min(w, VOXEL_BOX) * res, y + min(h, VOXEL_BOX) * res, 0.8 * span)
        pages, offset, total = [], 0, None
        while total is None or offset < total:
            reply = self._query(self.keys.service("voxels"), f"min={','.join(map(str, lo))};"
                                f"max={','.join(map(str, hi))};offset={offset}")
            if reply is None:
                return
            m = pb.VoxelSet.FromString(reply)
            centers = arrays.from_proto(m.centers, "centers", dtype="float32", shape=(None, 3))
            if len(centers) == 0:
                break
            pages.append(Voxels(centers, arrays.from_proto(m.occupancy, "occupancy", dtype="float32"),
                                arrays.from_proto(m.color, "color", dtype="uint8", shape=(len(centers), 3)),
                                arrays.from_proto(m.last_seen, "last_seen", dtype="float64"),
                                arrays.from_proto(m.min_distance, "min_distance", dtype="float32")))
            offset, total = m.offset + len(centers), m.total
        if pages:
            voxels = Voxels(*(np.concatenate([getattr(p, f) for p in pages]) for f in
                              ("centers", "occupancy", "color", "last_seen", "min_distance")))
            self.scene.at(self._now)
            self.scene.voxels(voxels, self._now, res)
            self.logged["voxels"] += 1
        if (reply := self._query(self.keys.service("stats"), "")) is not None:
            s = pb.MapStats.FromString(reply)
            self.scene.scalars("health", {f"map/{n}": getattr(s, n) for n in (
                "clouds_received", "clouds_inserted", "clouds_dropped", "messages_rejected", "leaves")})

    def _query(self, key: str, parameters: str, quiet: bool = False) -> bytes | None:
        """The first good reply; an error reply is counted (``quiet``: only logged at debug level: the
        decide node has nothing to show before its first tick, or for a scripted pattern)."""
        for reply in self.session.get(f"{key}?{parameters}" if parameters else key, timeout=5.0):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
            if quiet:
                _log.debug("%s: %s", key, reply.err.payload.to_string())
            else:
                self.rejects.reject(key, BadMessage("query failed", reply.err.payload.to_string()))
        return None
