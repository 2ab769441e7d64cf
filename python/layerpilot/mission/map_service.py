"""The map service: one fused voxel map, its layer windows, voxel boxes and snapshot policy.

Transport-free: the map server node decodes clouds and queries and calls it; the lock-step
evaluator calls it directly. Every request is checked before anything is allocated, so a
query for a window at x = 1e300 is a ``ValueError`` naming ``x``, not an overflow.

What a cloud may cost is bounded before it is inserted: its rays are at most the service's
``max_range`` long (a cloud's own value only lowers it), points outside the mission's
``Volume`` are dropped and counted, a cloud whose rays would take more than ``MAX_RAY_STEPS``
voxel steps is refused, and so is every cloud once the map holds ``max_map_mb``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from layerpilot.config import check_range
from layerpilot.grid import GridGeometry, GridWindow
from layerpilot.map import VoxelMap
from layerpilot.map.columns import ColumnLayers
from layerpilot.map.voxel_map import KEY_OFFSET, InsertResult, Voxels

_log = logging.getLogger("layerpilot.map_server")
COLUMN_LAYERS = ("observed", "elevation", "color", "last_seen", "min_distance")
MAX_WINDOW = 2048  # cells per side of a layer window
MAX_BOX = 512  # voxels per side of a voxel box
MAP_SIZE_EVERY = 2.0  # s between looks at the map's size (a look walks the tree: 80 ms at 3.6 M leaves)
MAX_RAY_STEPS = 1 << 27  # voxel steps of one cloud's rays (sum of ray lengths / resolution): a few s of insert


@dataclass(frozen=True)
class MapServiceConfig:
    """The ``[map_server]`` table of a mission file."""

    resolution: float = 1.0
    layers_rate: float = 1.0  # Hz (mission time): a layer set per vehicle this often
    window: tuple[float, float, int, int] = (-128.0, -128.0, 256, 256)  # x, y (south-west, m), w, h (cells)
    layers: tuple[str, ...] = COLUMN_LAYERS  # what the pilots need
    detail_margin: float = 30.0  # m: a vehicle's layer set is full within its pilot's reach + this of its pose
    snapshot: str = "runs/map.ot"  # "" = no snapshots
    snapshot_period: float = 30.0  # s (mission time)
    snapshot_keep: int = 3  # good snapshots kept (newest first)
    queue_size: int = 8  # clouds waiting for insertion; the oldest is dropped beyond
    max_range: float = 100.0  # m: the longest ray the map takes; a cloud's own max_range only lowers it
    max_map_mb: float = 512.0  # MB of map (octree, attributes, column index): clouds are refused beyond
    query_threads: int = 2
    max_voxels: int = 100_000  # voxels per voxel-query reply; more come in pages

    def __post_init__(self) -> None:
        check_range("map_server.resolution", self.resolution, 0.01, 10.0)
        check_range("map_server.layers_rate", self.layers_rate, 0.01, 100.0)
        check_range("map_server.snapshot_period", self.snapshot_period, 0.1)
        check_range("map_server.snapshot_keep", self.snapshot_keep, 1, 100)
        check_range("map_server.queue_size", self.queue_size, 1, 10_000)
        check_range("map_server.max_range", self.max_range, 0.1, 10_000.0)
        check_range("map_server.query_threads", self.query_threads, 1, 64)
        check_range("map_server.max_voxels", self.max_voxels, 1, 10_000_000)
        check_range("map_server.max_map_mb", self.max_map_mb, 1.0, 1_000_000.0)
        check_range("map_server.detail_margin", self.detail_margin, 0.0, 10_000.0)
        check_range("map_server.window width", self.window[2], 1, MAX_WINDOW)
        check_range("map_server.window height", self.window[3], 1, MAX_WINDOW)
        if not set(self.layers) <= set(COLUMN_LAYERS):
            raise ValueError(f"map_server.layers: unknown {sorted(set(self.layers) - set(COLUMN_LAYERS))}; "
                             f"known: {', '.join(COLUMN_LAYERS)}")


class CloudRefused(ValueError):
    """A cloud the map does not take; ``kind`` names why (counted per kind by the node)."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True)
class Volume:
    """The box of the map frame that clouds may reach: the mission's area widened by the sensor range."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    def __post_init__(self) -> None:
        if len(self.lo) != 3 or len(self.hi) != 3 or not all(
                math.isfinite(a) and math.isfinite(b) and a < b for a, b in zip(self.lo, self.hi)):
            raise ValueError(f"volume: need lo < hi, finite, on each of x, y, z; got {self.lo} .. {self.hi}")

    def inside(self, points: np.ndarray) -> np.ndarray:
        """A bool per point (N, 3): within the box."""
        return np.all((points >= np.asarray(self.lo, np.float32)) & (points <= np.asarray(self.hi, np.float32)), axis=1)


@dataclass(frozen=True)
class VoxelPage:
    voxels: Voxels
    offset: int
    total: int  # voxels in the box; the next page starts at offset + len(voxels)


class MapService:
    """Insert clouds, answer layer windows and voxel boxes, decide when to snapshot."""

    def __init__(self, cfg: MapServiceConfig, voxel_map: VoxelMap | None = None, volume: Volume | None = None) -> None:
        """``volume``: where clouds may reach (``mission.build.map_volume``); None = anywhere (tests, tools)."""
        self.cfg = cfg
        self.volume = volume
        self.map = voxel_map if voxel_map is not None else VoxelMap(cfg.resolution)
        if not np.isclose(self.map.resolution, cfg.resolution):
            raise ValueError(f"map resolution {self.map.resolution} != map_server.resolution {cfg.resolution}")
        self.clouds_inserted = 0
        self.points_inserted = 0
        self.points_outside = 0  # dropped: outside the volume
        self.last_stamp = 0.0  # newest mission-clock stamp inserted (stamps the layer sets)
        self._lock = threading.Lock()
        self._dirty = False
        self._last_snapshot = -math.inf
        self._map_bytes = (0, -math.inf)  # (total bytes, monotonic time looked at)

    def insert(self, points: np.ndarray, origin: np.ndarray, colors: np.ndarray | None, stamp: float,
               max_range: float | None = None) -> InsertResult:
        """One cloud into the map, its rays at most min(``max_range``, the service's) long.

        ValueError names a bad argument, ``CloudRefused`` a cloud over a cost limit; the map is then unchanged.
        """
        if not math.isfinite(stamp):
            raise ValueError(f"stamp: must be finite, got {stamp}")
        ray = min(max_range, self.cfg.max_range) if max_range else self.cfg.max_range
        points, origin = np.asarray(points, np.float32), np.asarray(origin, np.float64)
        if points.ndim != 2 or points.shape[1:] != (3,) or origin.shape != (3,):
            raise ValueError(f"points, origin: expected shapes (N, 3) and (3,), got {points.shape} and {origin.shape}")
        points, colors = self._within_volume(points, origin, colors)
        # a NaN point counts as a whole ray (fmin): the bound holds whatever the map then drops
        steps = float(np.fmin(np.linalg.norm(points - origin, axis=1), ray).sum()) / self.map.resolution
        if steps > MAX_RAY_STEPS:
            raise CloudRefused("too costly", f"{len(points)} rays of up to {ray:g} m are {steps:.3g} voxel steps, "
                                             f"more than {MAX_RAY_STEPS}")
        if (used := self.map_bytes()) >= self.cfg.max_map_mb * 1e6:
            raise CloudRefused("map full", f"the map holds {used / 1e6:.0f} MB, "
                                           f"map_server.max_map_mb = {self.cfg.max_map_mb:g}")
        return self._count(self.map.insert(points, origin, colors, stamp=stamp, max_range=ray), stamp)

    def map_bytes(self) -> int:
        """The map's memory (``VoxelMap.stats()["total_bytes"]``), looked at every ``MAP_SIZE_EVERY`` s at most."""
        used, when = self._map_bytes
        if time.monotonic() - when >= MAP_SIZE_EVERY:
            self._map_bytes = used, when = self.map.stats()["total_bytes"], time.monotonic()
        return used

    def _count(self, result: InsertResult, stamp: float) -> InsertResult:
        with self._lock:
            self.clouds_inserted += 1
            self.points_inserted += result.points_used
            self.last_stamp = max(self.last_stamp, stamp)
            self._dirty = True
        return result

    def _within_volume(self, points: np.ndarray, origin: np.ndarray,
                       colors: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """The points inside the volume (the rest counted in ``points_outside``); an origin outside is refused."""
        if self.volume is None:
            return points, colors
        if not self.volume.inside(origin.reshape(1, 3).astype(np.float32))[0]:
            raise CloudRefused("outside the area", f"origin {origin.tolist()} is outside the mission's volume "
                                                   f"{self.volume.lo} .. {self.volume.hi}")
        keep = self.volume.inside(points)
        if keep.all():
            return points, colors
        with self._lock:
            self.points_outside += int(len(keep) - keep.sum())
        return points[keep], None if colors is None else np.asarray(colors)[keep]

    def columns(self, x: float | None = None, y: float | None = None, w: int | None = None,
                h: int | None = None) -> ColumnLayers:
        """Column layers of a window (default: the configured one); a window off the map's key range is refused."""
        x0, y0, w0, h0 = self.cfg.window
        x, y = x0 if x is None else x, y0 if y is None else y
        w, h = w0 if w is None else w, h0 if h is None else h
        for name, value in (("x", x), ("y", y)):
            if not math.isfinite(value) or abs(value) / self.map.resolution > KEY_OFFSET - MAX_WINDOW - 1:
                raise ValueError(f"{name}: {value} is outside the map (|{name}| < "
                                 f"{(KEY_OFFSET - MAX_WINDOW - 1) * self.map.resolution:g} m)")
        if not (0 < w <= MAX_WINDOW and 0 < h <= MAX_WINDOW):
            raise ValueError(f"w, h: must be in 1..{MAX_WINDOW}, got {w}x{h}")
        return self.map.column_layers(x, y, int(w), int(h))

    @property
    def geometry(self) -> GridGeometry:
        """The grid of the configured window, snapped to the map's cells as ``columns()`` gives it."""
        x, y, w, h = self.cfg.window
        res = self.map.resolution
        return GridGeometry(math.floor(x / res) * res, math.floor(y / res) * res, res, int(w), int(h))

    def detail(self, x: float, y: float, reach: float) -> GridWindow:
        """The cells of the configured window a pilot at (x, y) reads, with ``detail_margin`` to spare.

        The pose a layer set is centred on is older than the pilot's next tick: the margin
        covers the flight in between (a pilot waits for a set that covers its tick).
        """
        return GridWindow.around(self.geometry, x, y, reach + self.cfg.detail_margin)

    def voxels(self, lo: np.ndarray, hi: np.ndarray, min_occupancy: float | None = None, offset: int = 0) -> VoxelPage:
        """Occupied voxels in a box, at most ``max_voxels`` per page from ``offset``."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError("min, max: expected three finite numbers each")
        if np.any(hi - lo > MAX_BOX * self.map.resolution):
            raise ValueError(f"box: at most {MAX_BOX} voxels per side")
        if offset < 0:
            raise ValueError(f"offset: must be >= 0, got {offset}")
        v = self.map.voxels(lo, hi, min_occupancy)
        end = min(len(v), offset + self.cfg.max_voxels)
        page = Voxels(*(getattr(v, f)[offset:end] for f in ("centers", "occupancy", "color", "last_seen",
                                                            "min_distance")))
        return VoxelPage(page, offset, len(v))

    # --- snapshots ------------------------------------------------------------------------

    def snapshot_due(self, now: float) -> bool:
        """A snapshot is due when the map changed and ``snapshot_period`` passed since the last one."""
        return bool(self.cfg.snapshot) and self._dirty and now - self._last_snapshot >= self.cfg.snapshot_period

    def snapshot(self, now: float | None = None) -> int:
        """Write the map to the snapshot store; returns the bytes written."""
        if not self.cfg.snapshot:
            raise ValueError("map_server.snapshot: no snapshot path configured")
        from layerpilot.map.snapshots import SnapshotStore

        self._dirty = False
        if now is not None:
            self._last_snapshot = now
        return SnapshotStore(Path(self.cfg.snapshot), self.cfg.snapshot_keep).save(self.map)

    @classmethod
    def start(cls, cfg: MapServiceConfig, volume: Volume | None = None) -> "MapService":
        """The service on the newest good snapshot, or on an empty map (damage is logged, never fatal)."""
        if not cfg.snapshot:
            return cls(cfg, volume=volume)
        from layerpilot.map.snapshots import SnapshotStore

        m, events = SnapshotStore(Path(cfg.snapshot), cfg.snapshot_keep).load_newest_good(cfg.resolution)
        if m is None:
            if Path(cfg.snapshot).exists() or events:
                _log.error("no good snapshot at %s: starting with an empty map", cfg.snapshot)
            return cls(cfg, volume=volume)
        _log.info("reloaded snapshot %s (%d leaves)", cfg.snapshot, m.stats()["leaves"])
        return cls(cfg, m, volume)
