"""The map server node: the mission's MapService on the bus, one fused map for every vehicle.

Clouds from ``layerpilot/<vehicle>/cloud`` (the mission's vehicles only) are decoded on
Zenoh's thread and queued; one worker inserts them (the C++ insert releases the GIL), within
the service's cost limits: rays of at most ``map_server.max_range``, points inside the
mission's volume (``mission.build.map_volume``), a map of at most ``max_map_mb``. The
queue is bounded: when clouds come faster than they can be inserted the oldest is dropped
and counted. Layer sets are published at a fixed rate, each in full only around its vehicle's
newest pose (its home before the first; ``MapService.detail``), so a square-kilometre area
fits the bus's layer-set cap; queries are answered by a small
thread pool (every query gets a reply, an error naming the problem if need be), and the
service's snapshot policy is checked twice a second.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import zenoh

from layerpilot.bus import arrays, keys
from layerpilot.bus.guard import guarded, query_params
from layerpilot.bus.layerset import encode_columns
from layerpilot.bus.messages import CloudMessage, State, decode_cloud, decode_state
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.bus.session import publish
from layerpilot.mission.build import map_volume
from layerpilot.missionfile import Mission
from layerpilot.mission.map_service import COLUMN_LAYERS, CloudRefused, MapService
from layerpilot.mission.pipeline import MissionPipeline
from layerpilot.nodes.queue import DropOldest
from layerpilot.nodes.supervise import Supervisor

_log = logging.getLogger("layerpilot.map_server")
SNAPSHOT_CHECK = 0.5  # s between looks at the snapshot policy
WAIT = 0.5  # s a worker waits for work before it beats its heartbeat again
LAYER_CACHE = 16  # encoded layer sets kept for the current map revision (distinct windows asked for)


class MapServer:
    def __init__(self, session: zenoh.Session, mission: Mission, supervisor: Supervisor | None = None) -> None:
        self.session = session
        self.supervisor = supervisor or Supervisor(_log)
        self.cfg = mission.map_server
        self.vehicles = tuple(mission.vehicles)
        self.rejects = Rejects(_log)
        self.queue: DropOldest[CloudMessage] = DropOldest(self.cfg.queue_size)
        # clouds reach the mission's area only
        self.pipeline = MissionPipeline(mission.core, {"map"}, map_service=MapService.start(self.cfg, map_volume(mission.core)))
        self.service = self.pipeline.map
        self.layer_sets_published = 0
        self.queries_answered = 0
        self.snapshots_written = 0
        self._stop = threading.Event()
        self._save_lock = threading.Lock()
        self._pool = ThreadPoolExecutor(self.cfg.query_threads, thread_name_prefix="map-query")
        self._decls: list = []
        self._next_publish = time.monotonic()
        self._layer_cache: dict[tuple, tuple[int, bytes]] = {}  # window -> (map revision, encoded layer set)
        self._layer_cache_lock = threading.Lock()

    @property
    def map(self):
        return self.service.map

    # --- lifecycle ------------------------------------------------------------------------

    def start(self) -> None:
        s = self.session
        self._decls.append(s.declare_subscriber(keys.all_vehicles("cloud"),
                                                guarded(decode_cloud, self._enqueue, self.rejects, self.supervisor)))
        self._decls.append(s.declare_subscriber(keys.all_vehicles("pose"),
                                                guarded(decode_state, self._on_pose, self.rejects, self.supervisor)))
        for name in keys.SERVICES:
            self._decls.append(s.declare_queryable(f"{keys.PREFIX}/*/map/{name}",
                                                   lambda q, name=name: self._on_query(q, name)))
        for iteration, name in ((self._insert_one, "insert"), (self._publish_due, "publish"),
                                (self._snapshot_due, "snapshot")):
            self.supervisor.start(f"map-{name}", iteration)

    def stop(self) -> None:
        """Stop serving, insert every cloud that was received, write a last snapshot."""
        self._stop.set()
        self.queue.close()
        for d in self._decls:
            d.undeclare()
        self.supervisor.join()
        self._pool.shutdown(wait=True)
        for message in self.queue.rest():  # received before the subscriptions ended: the map keeps them
            self._insert(message)
        if self.service.snapshot_due(float("inf")):
            self.snapshot()

    # --- clouds ---------------------------------------------------------------------------

    def _enqueue(self, cloud: CloudMessage, key: str) -> None:
        vehicle = keys.vehicle_of(key)
        if vehicle not in self.vehicles:  # per-vehicle state only for the mission's vehicles
            self.rejects.reject(key, BadMessage("unknown vehicle", f"{vehicle!r} is not one of {self.vehicles}"))
            return
        self.queue.put(cloud)

    def _on_pose(self, state: State, key: str) -> None:
        if state.vehicle in self.vehicles:  # other vehicles' poses are not ours to serve
            self.pipeline.pose(state.vehicle, state.stamp, state.pose)

    def _insert_one(self) -> bool:
        if (message := self.queue.get(timeout=WAIT)) is None:
            return not self.queue.closed
        self._insert(message)
        return True

    def _insert(self, message: CloudMessage) -> None:
        c = message.cloud
        try:
            self.pipeline.cloud(message.vehicle, c, message.max_range or None)
        except ValueError as exc:  # the cloud's fault (shape, NaN origin, a cost limit): rejected with the reason
            kind = exc.kind if isinstance(exc, CloudRefused) else "insert failed"
            self.rejects.reject(f"{keys.PREFIX}/{message.vehicle}/cloud", BadMessage(kind, str(exc)))

    # --- layer sets -----------------------------------------------------------------------

    def layer_set(self, vehicle: str, x: float | None = None, y: float | None = None, w: int | None = None,
                  h: int | None = None, names: tuple[str, ...] | None = None) -> bytes:
        """A window's column layers, encoded once per map change: every reader asking for the same
        window between two insertions (the periodic publisher, pilots, viewers) shares the bytes.

        No window given: the configured one, in full only where the vehicle's pilot reads
        (around its newest pose), as it is published.
        """
        names = names or self.cfg.layers
        revision = self.service.clouds_inserted  # read first: a cloud landing meanwhile makes the next ask miss
        near = None
        if x is None and y is None and w is None and h is None and vehicle in self.vehicles:
            near = self.pipeline.detail(vehicle)
        key = (vehicle, x, y, w, h, names, near)
        with self._layer_cache_lock:
            hit = self._layer_cache.get(key)
        if hit is not None and hit[0] == revision:
            return hit[1]
        data = encode_columns(self.service.columns(x, y, w, h), self.service.last_stamp, vehicle, names, near)
        with self._layer_cache_lock:
            for k in [k for k, (rev, _) in self._layer_cache.items() if rev != revision]:
                del self._layer_cache[k]  # an older map's
            if len(self._layer_cache) < LAYER_CACHE:
                self._layer_cache[key] = (revision, data)
        return data

    def _publish_due(self) -> bool:
        """A layer set per mission vehicle every 1 / layers_rate s (the transport's pacing: wall clock).

        From the start, an empty map too: a drone whose stereo needs motion to give its first cloud
        must get a first decision (the pilot's fallback flies it into the area), as in lock-step.
        """
        if self._stop.wait(min(WAIT, max(0.0, self._next_publish - time.monotonic()))):
            return False
        if time.monotonic() < self._next_publish:
            return True
        self._next_publish = max(self._next_publish + 1.0 / self.cfg.layers_rate, time.monotonic() - 1.0)
        for v in self.vehicles:
            key = keys.Keys(v).layers
            try:
                publish(self.session, key, self.layer_set(v))
                self.layer_sets_published += 1
            except ValueError as exc:  # e.g. the configured window does not fit in a layer set
                self.rejects.reject(key, BadMessage("publish failed", str(exc)))
        return True

    # --- snapshots ------------------------------------------------------------------------

    def snapshot(self) -> int:
        """Write a snapshot now (saves are serialized); returns its size in bytes."""
        with self._save_lock:
            size = self.service.snapshot(self.service.last_stamp)
            self.snapshots_written += 1
            return size

    def _snapshot_due(self) -> bool:
        if self._stop.wait(SNAPSHOT_CHECK):
            return False
        if self.service.snapshot_due(self.service.last_stamp):
            self.snapshot()  # a full disk raises OSError: the supervisor counts it, the map serves on
        return True

    # --- queries --------------------------------------------------------------------------

    def _on_query(self, query: zenoh.Query, service: str) -> None:
        # answered off Zenoh's thread so that a slow query never blocks the others
        try:
            self._pool.submit(self._answer, query, service)
        except RuntimeError:  # shutting down
            query.reply_err(b"map server is stopping")
            query.drop()

    def _answer(self, query: zenoh.Query, service: str) -> None:
        """``service``: the queryable that got it (a selector like ``map/*`` reaches every one)."""
        key = str(query.key_expr)
        try:
            vehicle = keys.vehicle_of(key)
            if vehicle != "*":
                keys.check_vehicle(vehicle)
            payload = getattr(self, f"_query_{service}")(vehicle, query_params(query))
            query.reply(f"{keys.PREFIX}/{vehicle}/map/{service}" if vehicle != "*" else query.key_expr, payload)
            self.queries_answered += 1
        except Exception as exc:  # every query gets an answer: an error naming the problem
            error = exc if isinstance(exc, BadMessage) else BadMessage(f"bad query ({type(exc).__name__})", str(exc))
            self.rejects.reject(key, error)
            query.reply_err(str(error).encode())
        finally:
            query.drop()

    def _query_layers(self, vehicle: str, p: dict[str, str]) -> bytes:
        x, y = _num(p, "x", None, optional=True), _num(p, "y", None, optional=True)
        w, h = _num(p, "w", None, optional=True), _num(p, "h", None, optional=True)
        names = tuple(p["layers"].split(",")) if p.get("layers") else COLUMN_LAYERS
        return self.layer_set(vehicle, x, y, None if w is None else int(w), None if h is None else int(h), names)

    def _query_stats(self, vehicle: str, p: dict[str, str]) -> bytes:
        return self.stats_message().SerializeToString()

    def stats_message(self) -> pb.MapStats:
        s = self.map.stats()
        svc = self.service
        m = pb.MapStats(stamp=svc.last_stamp, resolution=self.map.resolution, leaves=s["leaves"], nodes=s["nodes"],
                        tree_bytes=s["tree_bytes"], clouds_received=self.queue.received,
                        clouds_inserted=svc.clouds_inserted, clouds_dropped=self.queue.dropped,
                        messages_rejected=self.rejects.total, points_inserted=svc.points_inserted,
                        snapshots_written=self.snapshots_written)
        for attr in ("bounds_min", "bounds_max"):
            v = getattr(m, attr)
            v.x, v.y, v.z = (float(c) for c in s[attr])
        return m

    def _query_save(self, vehicle: str, p: dict[str, str]) -> bytes:
        if not self.cfg.snapshot:
            raise BadMessage("bad query", "this map server has no snapshot path configured")
        size = self.snapshot()
        return pb.SaveReply(path=str(Path(self.cfg.snapshot).resolve()), bytes=size).SerializeToString()

    def _query_octree(self, vehicle: str, p: dict[str, str]) -> bytes:
        """The whole map as an OctoMap ``.bt`` stream (occupancy only): what octomap_msgs carries."""
        return self.map.to_bytes(".bt")

    def _query_voxels(self, vehicle: str, p: dict[str, str]) -> bytes:
        occ = _num(p, "occ", None, optional=True)
        offset = _num(p, "offset", None, optional=True)
        page = self.service.voxels(_vec3(p, "min"), _vec3(p, "max"), occ, 0 if offset is None else int(offset))
        m = pb.VoxelSet(offset=page.offset, total=page.total)
        for name in ("centers", "occupancy", "color", "last_seen", "min_distance"):
            arrays.to_proto(getattr(page.voxels, name), getattr(m, name))
        return m.SerializeToString()


def _num(p: dict[str, str], name: str, default: float | None, optional: bool = False) -> float | None:
    if name not in p:
        if default is None and not optional:
            raise BadMessage("bad query", f"{name}: missing")
        return default
    try:
        value = float(p[name])
    except ValueError:
        raise BadMessage("bad query", f"{name}: not a number: {p[name]!r}") from None
    if not np.isfinite(value):
        raise BadMessage("bad query", f"{name}: not finite")
    return value


def _vec3(p: dict[str, str], name: str) -> np.ndarray:
    if name not in p:
        raise BadMessage("bad query", f"{name}: missing (expected x,y,z)")
    try:
        v = np.array([float(s) for s in p[name].split(",")])
    except ValueError:
        raise BadMessage("bad query", f"{name}: not numbers: {p[name]!r}") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise BadMessage("bad query", f"{name}: expected three finite numbers, got {p[name]!r}")
    return v
