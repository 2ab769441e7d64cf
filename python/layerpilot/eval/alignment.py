"""Scoring up to GNSS's common offset: the best translation between an estimated map and the truth.

No pose refinement removes the offset that every GNSS position shares (it needs ground
control); surveyors state accuracy after removing it and SLAM benchmarks align before they
score (TUM RGB-D's absolute trajectory error, Tanks and Temples' ICP before its F-score).
So the headline map metrics are taken after removing a single translation between the
estimated map and the true world, and the same metrics without it (``*_absolute``) stand
beside them, with the translation itself (``offset_x/y/z``: estimated minus true).

The translation is a whole number of voxels (shifted voxel centres stay on the lattice and
a shifted column grid is exact). With the camera poses the map was built from and the true
ones (the lock-step evaluator has both), it is their common offset (``pose_errors.common_offset``,
rounded to voxels): exactly what GNSS shares, and exactly 0 with perfect sensors, whatever
the map's own errors. With maps alone it is searched (``best_offset``: the capped chamfer
distance, kept only if it lowers it), which also takes up a systematic shift of the map itself.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Sequence

import numpy as np
from scipy.spatial import cKDTree

from layerpilot.eval.metrics import D_V, ABOVE_GT, MAP_METRICS, area_metrics, voxel_metrics
from layerpilot.eval.pose_errors import StampedPose, common_offset
from layerpilot.grid import GridGeometry

if TYPE_CHECKING:  # the C++ map is imported only where a map is used
    from layerpilot.map import VoxelMap
    from layerpilot.map.columns import ColumnLayers

OFFSET_KEYS = ["offset_x", "offset_y", "offset_z"]
SCORE_NAMES = MAP_METRICS + [f"{k}_absolute" for k in MAP_METRICS] + OFFSET_KEYS
SEARCH_STEPS = (8, 4, 2, 1)  # voxels, coarse to fine, from 0
WARM_STEPS = (2, 1)  # from the last offset: GNSS's error wanders slowly between two samples
MAX_SEARCH_POINTS = 8_000  # per map during the search (evenly strided); the scores use every voxel
MAX_OFFSET = 30.0  # metres per axis; several times a consumer receiver's error
_DIRECTIONS = [d for d in itertools.product((-1, 0, 1), repeat=3) if d != (0, 0, 0)]


def _strided(points: np.ndarray, limit: int) -> np.ndarray:
    return points[:: max(1, math.ceil(len(points) / limit))]


class _CappedChamfer:
    """Mean capped nearest distance both ways between ``est - offset`` and ``gt``, per whole-voxel offset."""

    def __init__(self, est: np.ndarray, gt: np.ndarray, resolution: float, cap: float) -> None:
        self.est, self.gt = _strided(est, MAX_SEARCH_POINTS), _strided(gt, MAX_SEARCH_POINTS)
        self.est_tree, self.gt_tree = cKDTree(self.est), cKDTree(self.gt)
        self.resolution, self.cap = resolution, cap
        self.cache: dict[tuple[int, int, int], float] = {}

    def __call__(self, key: tuple[int, int, int]) -> float:
        if key not in self.cache:
            o = np.array(key, np.float64) * self.resolution
            d_est, _ = self.gt_tree.query(self.est - o, distance_upper_bound=self.cap)
            d_gt, _ = self.est_tree.query(self.gt + o, distance_upper_bound=self.cap)
            self.cache[key] = float(np.minimum(d_est, self.cap).mean() + np.minimum(d_gt, self.cap).mean())
        return self.cache[key]


def best_offset(est: np.ndarray, gt: np.ndarray, resolution: float, start: np.ndarray | None = None,
                cap: float = D_V, max_offset: float = MAX_OFFSET) -> np.ndarray:
    """The whole-voxel translation (est minus truth, metres) that best lays voxel centres ``est`` onto ``gt``.

    A pattern search over the 26 neighbours in steps of 8, 4, 2, 1 voxels from 0, or of 2, 1 voxels
    from ``start`` (a mission passes its last offset, which GNSS's error changes slowly);
    the result is kept only if its capped chamfer distance is strictly below the one at 0, else it
    is exactly 0.
    """
    est, gt = np.asarray(est, np.float64), np.asarray(gt, np.float64)
    for name, arr in (("est", est), ("gt", gt)):
        if arr.ndim != 2 or arr.shape[1] != 3 or not np.all(np.isfinite(arr)):
            raise ValueError(f"{name}: expected finite points of shape (N, 3), got {arr.shape}")
    if not resolution > 0:
        raise ValueError(f"resolution: must be > 0, got {resolution}")
    zero = np.zeros(3)
    if len(est) == 0 or len(gt) == 0:
        return zero
    cost = _CappedChamfer(est, gt, resolution, cap)
    bound = int(max_offset // resolution)
    first = zero if start is None else np.clip(np.round(np.asarray(start, np.float64) / resolution), -bound, bound)
    best = tuple(int(v) for v in first)
    for step in SEARCH_STEPS if start is None else WARM_STEPS:
        while True:
            moves = [tuple(b + step * d for b, d in zip(best, direction)) for direction in _DIRECTIONS]
            moves = [m for m in moves if max(abs(v) for v in m) <= bound]
            candidate = min(moves, key=cost)
            if not cost(candidate) < cost(best):
                break
            best = candidate
    if not cost(best) < cost((0, 0, 0)):
        return zero
    return np.array(best, np.float64) * resolution


def _shifted(geometry: GridGeometry, offset: np.ndarray) -> GridGeometry:
    return replace(geometry, origin_x=geometry.origin_x + float(offset[0]),
                   origin_y=geometry.origin_y + float(offset[1]))


@dataclass(frozen=True)
class MapSnapshot:
    """What the scores read of the two maps at one moment (copies): the scoring itself, the costly
    nearest-voxel searches, can then run beside the mission while the maps change."""

    now: float
    offset: np.ndarray
    gt: np.ndarray
    views: tuple[tuple["ColumnLayers", np.ndarray], ...]  # (columns, voxel centres) absolute, then aligned
    aoi: np.ndarray
    d_v: float

    def scores(self) -> dict[str, float]:
        """Every name in ``SCORE_NAMES``: the aligned metrics, the absolute ones and the offset."""
        metrics = [self._metrics(columns, est) for columns, est in self.views]
        absolute, aligned = metrics[0], metrics[-1]
        return {**aligned, **{f"{k}_absolute": v for k, v in absolute.items()},
                **dict(zip(OFFSET_KEYS, (float(v) for v in self.offset)))}

    def _metrics(self, columns: "ColumnLayers", est: np.ndarray) -> dict[str, float]:
        area = area_metrics(columns, self.aoi, self.now)
        voxels = voxel_metrics(est, self.gt, self.d_v).as_dict()
        return {k: v for k, v in {**area.as_dict(), **voxels}.items() if k in MAP_METRICS}


@dataclass
class MapScorer:
    """The map metrics over a mission's area, both aligned (headline names) and absolute.

    Keeps the last offset it found: the next search starts there.
    """

    geometry: GridGeometry
    aoi: np.ndarray
    box_min: np.ndarray
    box_max: np.ndarray
    d_v: float = D_V
    min_occupancy: float = ABOVE_GT
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))  # the last one the scores used
    searched: bool = False  # once maps had something to align, searches start from ``offset``

    names = SCORE_NAMES

    def snapshot(self, est_map: "VoxelMap", gt_map: "VoxelMap", now: float,
                 poses: tuple[Sequence[StampedPose], Sequence[StampedPose]] | None = None) -> MapSnapshot:
        """The estimated and ground-truth maps at ``now``, aligned, as :meth:`MapSnapshot.scores` reads them.

        ``poses``: (true, placed) camera poses, the placed ones those the map's clouds were placed with;
        the offset is then theirs (0 while either is empty), else the maps' (``best_offset``)."""
        if not np.isclose(est_map.resolution, gt_map.resolution):
            raise ValueError(f"gt_map: resolution {gt_map.resolution} != est_map's {est_map.resolution}")
        gt = gt_map.voxels(self.box_min, self.box_max, self.min_occupancy).centers
        est = est_map.voxels(self.box_min, self.box_max, self.min_occupancy).centers
        res = est_map.resolution
        if poses is not None:
            truth, placed = poses
            # whole voxels (+ 0.0: a rounded -0.0 is reported as 0)
            self.offset = np.round(common_offset(truth, placed) / res) * res + 0.0 if truth and placed else np.zeros(3)
        elif len(est) and len(gt):  # the first search with something to align is the coarse one
            self.offset = best_offset(est, gt, res, self.offset if self.searched else None, self.d_v)
            self.searched = True
        views = [(est_map.column_layers_for(self.geometry), est)]
        if self.offset.any():
            o = self.offset
            views.append((est_map.column_layers_for(_shifted(self.geometry, o)),
                          est_map.voxels(self.box_min + o, self.box_max + o, self.min_occupancy).centers - o))
        return MapSnapshot(now, self.offset.copy(), gt, tuple(views), self.aoi, self.d_v)

    def __call__(self, est_map: "VoxelMap", gt_map: "VoxelMap", now: float,
                 poses: tuple[Sequence[StampedPose], Sequence[StampedPose]] | None = None) -> dict[str, float]:
        """Every name in ``SCORE_NAMES`` for the estimated map against the ground-truth one at ``now``."""
        return self.snapshot(est_map, gt_map, now, poses).scores()
