"""The map server daemon: one fused VoxelMap for every vehicle on the bus.

Clouds from ``layerpilot/*/cloud`` are decoded on Zenoh's thread and queued; one worker
inserts them (the C++ insert releases the GIL). The queue is bounded: when clouds come
faster than they can be inserted the oldest is dropped and counted. Layer sets are
published at a fixed rate, queries are answered by a small thread pool, the map is
snapshotted atomically every period and reloaded at start.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zenoh

from layerpilot.bus import arrays, keys
from layerpilot.bus.guard import guarded, query_params
from layerpilot.bus.layerset import COLUMN_ENCODINGS, LayerSet, column_arrays, encode_layer_set
from layerpilot.bus.messages import Cloud, decode_cloud
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.bus.session import publish
from layerpilot.config import check_range
from layerpilot.map import VoxelMap
from layerpilot.nodes.queue import DropOldest

_log = logging.getLogger("layerpilot.map_server")
MAX_WINDOW = 2048  # cells per side a query may ask for


@dataclass(frozen=True)
class MapServerConfig:
    """The ``[map_server]`` table of a mission file."""

    resolution: float = 0.5
    layers_rate: float = 1.0  # Hz
    window: tuple[float, float, int, int] = (-64.0, -64.0, 256, 256)  # published: x, y (south-west, m), w, h (cells)
    layers: tuple[str, ...] = ("observed", "elevation", "color", "last_seen", "min_distance")  # what decide needs
    snapshot: str = "runs/map.ot"  # "" = no snapshots
    snapshot_period: float = 30.0  # s
    queue_size: int = 8
    max_range: float = 60.0  # m, for clouds that do not say
    query_threads: int = 2

    def __post_init__(self) -> None:
        check_range("map_server.resolution", self.resolution, 0.01, 10.0)
        check_range("map_server.layers_rate", self.layers_rate, 0.01, 100.0)
        check_range("map_server.snapshot_period", self.snapshot_period, 0.1)
        check_range("map_server.queue_size", self.queue_size, 1, 10_000)
        check_range("map_server.max_range", self.max_range, 0.1)
        check_range("map_server.query_threads", self.query_threads, 1, 64)
        check_range("map_server.window width", self.window[2], 1, MAX_WINDOW)
        check_range("map_server.window height", self.window[3], 1, MAX_WINDOW)
        if not set(self.layers) <= set(COLUMN_ENCODINGS):
            raise ValueError(f"map_server.layers: unknown {sorted(set(self.layers) - set(COLUMN_ENCODINGS))}")


@dataclass
class Counters:
    queue: DropOldest[Cloud]  # counts the clouds received and dropped where they are handed over
    clouds_inserted: int = 0
    points_inserted: int = 0
    snapshots_written: int = 0
    layer_sets_published: int = 0
    queries_answered: int = 0
    last_stamp: float = 0.0  # newest mission-clock stamp seen (stamps the layer sets)
    vehicles: set[str] = field(default_factory=set)

    @property
    def clouds_received(self) -> int:
        return self.queue.received

    @property
    def clouds_dropped(self) -> int:
        return self.queue.dropped


class MapServer:
    def __init__(self, session: zenoh.Session, cfg: MapServerConfig) -> None:
        self.session = session
        self.cfg = cfg
        self.rejects = Rejects(_log)
        self.queue: DropOldest[Cloud] = DropOldest(cfg.queue_size)
        self.counters = Counters(self.queue)
        self.map = self._load_or_new()
        self._lock = threading.Lock()  # counters shared by the Zenoh callback and the workers
        self._stop = threading.Event()
        self._pool = ThreadPoolExecutor(cfg.query_threads, thread_name_prefix="map-query")
        self._dirty = False
        self._threads: list[threading.Thread] = []
        self._decls: list = []

    def _load_or_new(self) -> VoxelMap:
        path = Path(self.cfg.snapshot) if self.cfg.snapshot else None
        if path is not None and path.is_file():
            m = VoxelMap.load(path)
            if not np.isclose(m.resolution, self.cfg.resolution):
                raise ValueError(f"snapshot {path} has resolution {m.resolution}, config says {self.cfg.resolution}")
            _log.info("reloaded snapshot %s (%d leaves)", path, m.stats()["leaves"])
            return m
        return VoxelMap(self.cfg.resolution)

    # --- lifecycle ------------------------------------------------------------------------

    def start(self) -> None:
        s = self.session
        self._decls.append(s.declare_subscriber(keys.all_vehicles("cloud"),
                                                guarded(decode_cloud, self._enqueue, self.rejects)))
        for name in keys.SERVICES:
            self._decls.append(s.declare_queryable(f"{keys.PREFIX}/*/map/{name}", self._on_query))
        for target, name in ((self._insert_loop, "insert"), (self._publish_loop, "publish"),
                             (self._snapshot_loop, "snapshot")):
            t = threading.Thread(target=target, name=f"map-{name}", daemon=True)
            t.start()
            self._threads.append(t)

    def stop(self) -> None:
        """Finish the cloud being inserted, stop serving, write a last snapshot."""
        self._stop.set()
        self.queue.close()
        for d in self._decls:
            d.undeclare()
        for t in self._threads:
            t.join()
        self._pool.shutdown(wait=True)
        if self.cfg.snapshot and self._dirty:
            self.snapshot()

    # --- clouds ---------------------------------------------------------------------------

    def _enqueue(self, cloud: Cloud, key: str) -> None:
        with self._lock:
            self.counters.vehicles.add(keys.vehicle_of(key))
        self.queue.put(cloud)

    def _insert_loop(self) -> None:
        while (cloud := self.queue.get()) is not None:
            try:
                result = self.map.insert(cloud.points, cloud.origin, cloud.colors, stamp=cloud.stamp,
                                         max_range=cloud.max_range or self.cfg.max_range)
            except ValueError as exc:
                self.rejects.reject(keys.PREFIX + f"/{cloud.vehicle}/cloud", BadMessage("insert failed", str(exc)))
                continue
            with self._lock:
                c = self.counters
                c.clouds_inserted += 1
                c.points_inserted += result.points_used
                c.last_stamp = max(c.last_stamp, cloud.stamp)
                self._dirty = True

    # --- layer sets -----------------------------------------------------------------------

    def layer_set(self, vehicle: str, x: float, y: float, w: int, h: int, names: tuple[str, ...]) -> bytes:
        cl = self.map.column_layers(x, y, w, h)
        return encode_layer_set(LayerSet(self.counters.last_stamp, vehicle, cl.geometry, column_arrays(cl, names)))

    def _publish_loop(self) -> None:
        period = 1.0 / self.cfg.layers_rate
        next_t = time.monotonic()
        x, y, w, h = self.cfg.window
        while not self._stop.wait(max(0.0, next_t - time.monotonic())):
            next_t += period
            with self._lock:
                vehicles = sorted(self.counters.vehicles)
            for v in vehicles:
                try:
                    publish(self.session, keys.Keys(v).layers, self.layer_set(v, x, y, w, h, self.cfg.layers))
                    self.counters.layer_sets_published += 1
                except ValueError as exc:  # e.g. the configured window does not fit in 1 MB
                    self.rejects.reject(keys.Keys(v).layers, BadMessage("publish failed", str(exc)))

    # --- snapshots ------------------------------------------------------------------------

    def snapshot(self) -> int:
        """Write the map atomically to the snapshot path; returns its size in bytes."""
        path = Path(self.cfg.snapshot)
        path.parent.mkdir(parents=True, exist_ok=True)
        self._dirty = False
        self.map.save(path)
        self.counters.snapshots_written += 1
        return path.stat().st_size

    def _snapshot_loop(self) -> None:
        if not self.cfg.snapshot:
            return
        while not self._stop.wait(self.cfg.snapshot_period):
            if self._dirty:
                self.snapshot()

    # --- queries --------------------------------------------------------------------------

    def _on_query(self, query: zenoh.Query) -> None:
        # answered off Zenoh's thread so that a slow query never blocks the others
        try:
            self._pool.submit(self._answer, query)
        except RuntimeError:  # shutting down
            query.reply_err(b"map server is stopping")

    def _answer(self, query: zenoh.Query) -> None:
        key = str(query.key_expr)
        try:
            vehicle = keys.vehicle_of(key)
            service = key.rsplit("/", 1)[-1]
            payload = getattr(self, f"_query_{service}")(vehicle, query_params(query))
            query.reply(query.key_expr, payload)
            self.counters.queries_answered += 1
        except (BadMessage, ValueError) as exc:
            self.rejects.reject(key, exc if isinstance(exc, BadMessage) else BadMessage("bad query", str(exc)))
            query.reply_err(str(exc).encode())
        finally:
            query.drop()

    def _query_layers(self, vehicle: str, p: dict[str, str]) -> bytes:
        x0, y0, w0, h0 = self.cfg.window
        x, y = _num(p, "x", x0), _num(p, "y", y0)
        w, h = int(_num(p, "w", w0)), int(_num(p, "h", h0))
        if not (0 < w <= MAX_WINDOW and 0 < h <= MAX_WINDOW):
            raise BadMessage("bad query", f"w, h: must be in 1..{MAX_WINDOW}, got {w}x{h}")
        names = tuple(p["layers"].split(",")) if p.get("layers") else tuple(COLUMN_ENCODINGS)
        return self.layer_set(vehicle, x, y, w, h, names)

    def _query_stats(self, vehicle: str, p: dict[str, str]) -> bytes:
        return self.stats_message().SerializeToString()

    def stats_message(self) -> pb.MapStats:
        s = self.map.stats()
        c = self.counters
        m = pb.MapStats(stamp=c.last_stamp, resolution=self.map.resolution, leaves=s["leaves"], nodes=s["nodes"],
                        tree_bytes=s["tree_bytes"], clouds_received=c.clouds_received,
                        clouds_inserted=c.clouds_inserted, clouds_dropped=c.clouds_dropped,
                        messages_rejected=self.rejects.total, points_inserted=c.points_inserted,
                        snapshots_written=c.snapshots_written)
        for attr in ("bounds_min", "bounds_max"):
            v = getattr(m, attr)
            v.x, v.y, v.z = (float(c) for c in s[attr])
        return m

    def _query_save(self, vehicle: str, p: dict[str, str]) -> bytes:
        if not self.cfg.snapshot:
            raise BadMessage("bad query", "this map server has no snapshot path configured")
        size = self.snapshot()
        return pb.SaveReply(path=str(Path(self.cfg.snapshot).resolve()), bytes=size).SerializeToString()

    def _query_voxels(self, vehicle: str, p: dict[str, str]) -> bytes:
        lo, hi = _vec3(p, "min"), _vec3(p, "max")
        if np.any(hi - lo > 512 * self.map.resolution):
            raise BadMessage("bad query", "box: at most 512 voxels per side")
        occ = _num(p, "occ", None) if "occ" in p else None
        v = self.map.voxels(lo, hi, occ)
        m = pb.VoxelSet()
        for name in ("centers", "occupancy", "color", "last_seen", "min_distance"):
            arrays.to_proto(getattr(v, name), getattr(m, name))
        return m.SerializeToString()


def _num(p: dict[str, str], name: str, default: float | None) -> float:
    if name not in p:
        if default is None:
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
