"""VoxelMap: the Python face of the C++ attribute octree (layerpilot._core)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from layerpilot import _core
from layerpilot.grid import GridGeometry
from layerpilot.map.columns import ColumnLayers
from layerpilot.map.files import MapFileError, read_checked, write_atomic

KEY_OFFSET = 32768  # OctoMap's key of the cell whose lower corner is the map origin
_NO_COLORS = np.zeros((0, 3), np.uint8)


@dataclass(frozen=True)
class SensorModel:
    """OctoMap's occupancy sensor model (probabilities; OctoMap's defaults)."""

    prob_hit: float = 0.7
    prob_miss: float = 0.4
    clamp_min: float = 0.1192
    clamp_max: float = 0.971
    occupied_threshold: float = 0.5

    def to_core(self) -> "_core._SensorModel":
        model = _core._SensorModel()
        for name in self.__dataclass_fields__:
            setattr(model, name, getattr(self, name))
        return model


@dataclass(frozen=True)
class InsertResult:
    points_used: int
    points_dropped: int  # NaN/inf, or outside the map's key range
    voxels_updated: int  # distinct voxels touched (free + occupied)
    voxels_occupied: int  # of which endpoint (hit) voxels


@dataclass(frozen=True)
class Voxels:
    """Voxels as arrays: (n, 3) centres and one attribute row each."""

    centers: np.ndarray  # float32 (n, 3)
    occupancy: np.ndarray  # float32 probability
    color: np.ndarray  # uint8 (n, 3)
    last_seen: np.ndarray  # float64 seconds, NaN = never hit
    min_distance: np.ndarray  # float32 metres, inf = never hit

    def __len__(self) -> int:
        return len(self.occupancy)


def _array(value: object, name: str, dtype: type, shape: tuple[int | None, ...]) -> np.ndarray:
    """Return ``value`` as a C-contiguous array of ``dtype``; ValueError names the argument."""
    arr = np.asarray(value)
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {arr.shape}")
    if arr.dtype != dtype:
        if dtype is np.uint8 or not np.issubdtype(arr.dtype, np.number):
            raise ValueError(f"{name}: expected dtype {np.dtype(dtype)}, got {arr.dtype}")
        arr = arr.astype(dtype)
    return np.ascontiguousarray(arr)


class VoxelMap:
    """A 3D occupancy map that remembers, per voxel, color, time last seen and closest view.

    Occupancy follows OctoMap exactly (log-odds, sensor model, clamping; insertion as
    OctoMap's discretized ``insertPointCloud``). The voxel color is the latest observation:
    the mean color of the frame's points that fell into the voxel. Thread-safe: inserts
    release the GIL and take a writer lock only to apply updates; every read shares the lock.
    """

    def __init__(self, resolution: float = 1.0, *, model: SensorModel | None = None, **model_args: float) -> None:
        if model is not None and model_args:
            raise ValueError("give either model= or sensor-model keywords, not both")
        self.model = model or SensorModel(**model_args)
        if not resolution > 0:
            raise ValueError(f"resolution: must be > 0, got {resolution}")
        self._core = _core._VoxelMap(float(resolution), self.model.to_core())

    @property
    def resolution(self) -> float:
        return self._core.resolution

    def insert(
        self,
        points: np.ndarray,
        origin: np.ndarray,
        colors: np.ndarray | None = None,
        stamp: float = 0.0,
        max_range: float = 100.0,
    ) -> InsertResult:
        """Insert one sensor frame: free space along each ray, occupied at each endpoint.

        Endpoints beyond ``max_range`` clear free space up to ``max_range`` only. NaN/inf points
        are dropped and counted. Occupied endpoint voxels get last seen = ``stamp``, min
        distance = min(previous, ray length) and the frame's color.
        """
        pts = _array(points, "points", np.float32, (None, 3))
        org = _array(origin, "origin", np.float64, (3,))
        if not np.all(np.isfinite(org)):
            raise ValueError(f"origin: must be finite, got {org}")
        cols = _NO_COLORS if colors is None else _array(colors, "colors", np.uint8, (len(pts), 3))
        if not np.isfinite(stamp):
            raise ValueError(f"stamp: must be finite, got {stamp}")
        if not max_range > 0:
            raise ValueError(f"max_range: must be > 0, got {max_range}")
        return InsertResult(*self._core.insert(pts, cols, org, float(stamp), float(max_range)))

    def column_layers(self, x: float, y: float, width: int, height: int) -> ColumnLayers:
        """Per-column summary of a window whose south-west corner is (x, y), snapped to the grid."""
        res = self.resolution
        kx = int(np.floor(x / res)) + KEY_OFFSET
        ky = int(np.floor(y / res)) + KEY_OFFSET
        if width <= 0 or height <= 0:
            raise ValueError(f"width, height: must be > 0, got {width}x{height}")
        geometry = GridGeometry((kx - KEY_OFFSET) * res, (ky - KEY_OFFSET) * res, res, int(width), int(height))
        observed, elevation, color, last_seen, min_distance = self._core.column_layers(kx, ky, int(width), int(height))
        return ColumnLayers(geometry, observed.view(bool), elevation, color, last_seen, min_distance)

    def column_layers_for(self, geometry: GridGeometry) -> ColumnLayers:
        """Column layers on a given grid (its resolution must be the map's)."""
        if not np.isclose(geometry.resolution, self.resolution):
            raise ValueError(f"geometry: resolution {geometry.resolution} != map resolution {self.resolution}")
        half = 0.5 * self.resolution
        return self.column_layers(geometry.origin_x + half, geometry.origin_y + half, geometry.width, geometry.height)

    def occupancy(self, points: np.ndarray) -> np.ndarray:
        """Occupancy probability at each point; NaN where the map knows nothing (unknown)."""
        return self._core.occupancy(_array(points, "points", np.float64, (None, 3)))

    def raycast(self, origin: np.ndarray, direction: np.ndarray, max_range: float = 100.0) -> np.ndarray | None:
        """Centre of the first occupied voxel along the ray (unknown counts as free), or None: OctoMap's castRay."""
        org = _array(origin, "origin", np.float64, (3,))
        d = _array(direction, "direction", np.float64, (3,))
        if not np.linalg.norm(d) > 0:
            raise ValueError("direction: must be non-zero")
        return self._core.raycast(org, d, float(max_range))

    def voxels(self, box_min: np.ndarray, box_max: np.ndarray, min_occupancy: float | None = None) -> Voxels:
        """Voxels whose centre lies in the box, with occupancy >= ``min_occupancy``.

        The default is the occupied voxels: occupancy >= the model's ``occupied_threshold``, as
        OctoMap's ``isNodeOccupied`` (the one definition the column layers, raycast and ``.bt`` use).
        """
        lo = _array(box_min, "box_min", np.float64, (3,))
        hi = _array(box_max, "box_max", np.float64, (3,))
        if np.any(lo > hi):
            raise ValueError(f"box_min {lo} must be <= box_max {hi}")
        thr = self.model.occupied_threshold if min_occupancy is None else float(min_occupancy)
        return Voxels(*self._core.voxels(lo, hi, thr))

    def to_bytes(self, suffix: str = ".ot") -> bytes:
        """The map as one OctoMap file stream: ``.ot`` with every attribute, ``.bt`` occupancy only.

        This is what ``save``/``export_bt`` write before the integrity footer; the snapshot store
        writes it too.
        """
        if suffix not in (".ot", ".bt"):
            raise ValueError(f"suffix: expected .ot or .bt, got {suffix!r}")
        return self._core.serialize(suffix == ".bt")

    def save(self, path: str | os.PathLike) -> int:
        """Write an OctoMap ``.ot`` file with every attribute; returns its size in bytes.

        Atomic (a uniquely named, fsynced temporary file renamed into place) and ending in an
        integrity footer that ``load`` checks and OctoMap's tools ignore.
        """
        path = Path(path)
        if path.suffix != ".ot":
            raise ValueError(f"path: save() writes .ot files, got {path.name}; use export_bt for .bt")
        return write_atomic(path, self.to_bytes(".ot"))

    def export_bt(self, path: str | os.PathLike) -> int:
        """Write a plain OctoMap ``.bt`` (occupancy only), readable by every OctoMap tool; returns its size.

        Atomic and with the integrity footer, as ``save``.
        """
        path = Path(path)
        if path.suffix != ".bt":
            raise ValueError(f"path: export_bt() writes .bt files, got {path.name}")
        return write_atomic(path, self.to_bytes(".bt"))

    @classmethod
    def load(cls, path: str | os.PathLike, *, model: SensorModel | None = None) -> "VoxelMap":
        """Read a ``.ot`` (layerpilot's, or stock OcTree/ColorOcTree) or ``.bt`` file, all of it or nothing.

        The integrity footer of a layerpilot file is checked, and every file's whole stream is
        validated (header, every node, the exact end) before the map is built: a truncated,
        garbled or padded file raises MapFileError (a ValueError) with one line naming the file
        and what is wrong.
        """
        path = Path(path)
        if path.suffix not in (".ot", ".bt"):
            raise ValueError(f"path: expected a .ot or .bt file, got {path.name}")
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such map file")
        stream = read_checked(path)
        self = cls.__new__(cls)
        self.model = model or SensorModel()
        try:
            self._core = _core._VoxelMap.parse(stream, self.model.to_core())
        except _core._MapFileError as exc:
            raise MapFileError(f"{path}: {exc}") from None
        return self

    def stats(self) -> dict:
        """Sizes (nodes, leaves, bytes, bytes per leaf) and metric bounds of known space.

        ``total_bytes`` is the whole map in memory: ``tree_bytes`` (nodes, attribute records,
        free lists) + ``column_index_bytes``; ``bytes_per_leaf`` divides it by the leaves.
        ``insert_scratch_bytes`` is the most working memory one insert has needed (freed after it).
        """
        s = self._core.stats()
        s["bytes_per_leaf"] = s["total_bytes"] / s["leaves"] if s["leaves"] else 0.0
        return s

