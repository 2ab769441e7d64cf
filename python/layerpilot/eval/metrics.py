"""The method paper's metrics: 2D ones over the column layers, 3D ones against ground truth.

2D metrics are taken over Z (area of interest, a boolean mask on the layers' grid) and
M (mapped columns: ``ColumnLayers.observed``). 3D metrics compare voxel centre sets:
V_est (mission map) and V_GT (the same mapping code fed ground-truth depth). The paper's
"3D recall" and "3D MSE" are computed exactly as it writes them; standard precision,
recall and F-score are given beside them (see docs/eval.md for how they differ).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

from layerpilot.grid import GridGeometry
from layerpilot.map.columns import ColumnLayers

if TYPE_CHECKING:  # the C++ map is imported only where a map is used
    from layerpilot.map import VoxelMap

DISTANCE_CAP = 100.0  # metres; the distance layer's cap, also applied here
D_V = 4.0  # metres; the paper's voxel match distance
GT_OCCUPANCY = 0.7  # voxels strictly above this occupancy count for the 3D metrics
# One hit from unknown gives exactly 0.7 (prob_hit); "above" therefore needs two hits.
_ABOVE_GT = float(np.nextafter(np.float32(GT_OCCUPANCY), np.float32(1.0)))
_MAX_PAIRS = 1 << 22  # candidate pairs examined per numpy batch (bounds memory)


@dataclass(frozen=True)
class AreaMetrics:
    percent_mapped: float  # 100 * |M and Z| / |Z|
    avg_time_since_observed: float  # seconds, mean over M and Z; NaN if empty
    avg_min_distance: float  # metres, mean over M and Z, capped; NaN if empty

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class VoxelMetrics:
    paper_recall: float  # |{v in V_est : d(v, V_GT) <= d_v}| / |V_GT| (can exceed 1)
    paper_mse: float  # mean over V_est of d(v, V_GT), metres (a mean distance, not squared)
    precision: float  # |{v in V_est : d(v, V_GT) <= d_v}| / |V_est|
    recall: float  # |{u in V_GT : d(u, V_est) <= d_v}| / |V_GT| (completeness)
    f_score: float  # harmonic mean of precision and recall
    n_est: int
    n_gt: int

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def disk_mask(geometry: GridGeometry, center: tuple[float, float], radius: float) -> np.ndarray:
    """Area of interest: cells whose centre lies within ``radius`` of ``center`` (x, y)."""
    if not radius > 0:
        raise ValueError(f"radius: must be > 0, got {radius}")
    xs, ys = geometry.cell_centers()
    return (xs - center[0]) ** 2 + (ys - center[1]) ** 2 <= radius**2


def area_metrics(layers: ColumnLayers, aoi: np.ndarray, now: float) -> AreaMetrics:
    """Percent of Z mapped, and mean time since observed / min distance over M and Z."""
    aoi = np.asarray(aoi)
    if aoi.shape != layers.geometry.shape or aoi.dtype != np.bool_:
        raise ValueError(f"aoi: expected bool {layers.geometry.shape}, got {aoi.dtype} {aoi.shape}")
    if not np.isfinite(now):
        raise ValueError(f"now: must be finite, got {now}")
    n_aoi = int(aoi.sum())
    if n_aoi == 0:
        raise ValueError("aoi: the area of interest is empty")
    mz = layers.observed & aoi
    n = int(mz.sum())
    if n == 0:
        return AreaMetrics(0.0, float("nan"), float("nan"))
    age = now - layers.last_seen[mz]
    dist = np.minimum(layers.min_distance[mz].astype(np.float64), DISTANCE_CAP)
    return AreaMetrics(100.0 * n / n_aoi, float(age.mean()), float(dist.mean()))


def _points(value: object, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite")
    return arr


def nearest_distances(
    points: np.ndarray, reference: np.ndarray, cell: float = D_V, max_distance: float = np.inf
) -> np.ndarray:
    """Exact Euclidean distance from each point to its nearest reference point.

    inf where there is no reference point, or none within ``max_distance`` (then the search
    stops early: that is all a match count needs). A hash grid of ``cell``-sized cubes: a
    query checks its own cell and the 26 around it, which settles every query whose best
    distance is <= ``cell``; the rest are retried on a grid 4x coarser, so far outliers cost
    few passes and the answer stays exact.
    """
    pts = _points(points, "points")
    ref = _points(reference, "reference")
    if not cell > 0:
        raise ValueError(f"cell: must be > 0, got {cell}")
    if not max_distance > 0:
        raise ValueError(f"max_distance: must be > 0, got {max_distance}")
    best = np.full(len(pts), np.inf)
    if len(pts) == 0 or len(ref) == 0:
        return best
    todo = np.arange(len(pts))
    lo = np.minimum(pts.min(0), ref.min(0))
    span = float(np.max(np.maximum(pts.max(0), ref.max(0)) - lo))
    while len(todo):
        best[todo] = _nearest_in_neighbourhood(pts[todo], ref, lo, cell)
        if cell > span:  # every reference point was within the 27 cells
            break
        todo = todo[best[todo] > cell]
        if cell >= max_distance:  # the rest are farther than max_distance
            best[todo] = np.inf
            break
        cell *= 4.0
    return best


def _nearest_in_neighbourhood(pts: np.ndarray, ref: np.ndarray, lo: np.ndarray, cell: float) -> np.ndarray:
    """Nearest reference point among the query's own and 26 neighbouring cells (inf if none)."""
    qc = np.floor((pts - lo) / cell).astype(np.int64) + 1  # +1: neighbours stay >= 0
    rc = np.floor((ref - lo) / cell).astype(np.int64) + 1
    dims = np.maximum(qc.max(0), rc.max(0)) + 2
    rkey = (rc[:, 0] * dims[1] + rc[:, 1]) * dims[2] + rc[:, 2]
    order = np.argsort(rkey, kind="stable")
    rsorted = ref[order]
    cells, cell_start, cell_count = np.unique(rkey[order], return_index=True, return_counts=True)
    # Queries sorted by cell key: a neighbour offset adds a constant to the key, so every
    # needle array below is sorted too, which keeps searchsorted cache-friendly.
    qkey = (qc[:, 0] * dims[1] + qc[:, 1]) * dims[2] + qc[:, 2]
    qorder = np.argsort(qkey, kind="stable")
    qkey, qpts = qkey[qorder], pts[qorder]
    best = np.full(len(pts), np.inf)
    qxyz = [np.ascontiguousarray(qpts[:, a]) for a in range(3)]
    rxyz = [np.ascontiguousarray(rsorted[:, a]) for a in range(3)]
    own_cell_first = [(0, 0, 0)] + [(a - 1, b - 1, c - 1) for a, b, c in np.ndindex(3, 3, 3) if (a, b, c) != (1, 1, 1)]
    active = np.arange(len(pts))
    for i, (dx, dy, dz) in enumerate(own_cell_first):
        if i == 1:  # queries sitting on a reference point (distance 0) are done
            active = np.flatnonzero(best > 0)
        key = qkey[active] + (dx * dims[1] + dy) * dims[2] + dz
        slot = np.minimum(np.searchsorted(cells, key), len(cells) - 1)
        hit = np.flatnonzero(cells[slot] == key)
        has = active[hit]
        start, count = cell_start[slot[hit]], cell_count[slot[hit]]
        cum = np.cumsum(count)
        first = 0
        while first < len(has):  # batches of at most _MAX_PAIRS candidate pairs
            base = cum[first - 1] if first else 0
            last = max(int(np.searchsorted(cum, base + _MAX_PAIRS, "right")), first + 1)
            q, n = has[first:last], count[first:last]
            group = np.cumsum(n) - n
            qi = np.repeat(q, n)
            ri = np.repeat(start[first:last] - group, n) + np.arange(len(qi))
            d2 = sum((q_a[qi] - r_a[ri]) ** 2 for q_a, r_a in zip(qxyz, rxyz))
            best[q] = np.minimum(best[q], np.minimum.reduceat(d2, group))
            first = last
    out = np.empty(len(pts))
    out[qorder] = np.sqrt(best)
    return out


def voxel_metrics(est: np.ndarray, gt: np.ndarray, d_v: float = D_V) -> VoxelMetrics:
    """3D metrics of estimated voxel centres against ground-truth ones at match distance d_v."""
    est = _points(est, "est")
    gt = _points(gt, "gt")
    if not d_v > 0:
        raise ValueError(f"d_v: must be > 0, got {d_v}")
    nan = float("nan")
    d_est = nearest_distances(est, gt, d_v / 4)  # most matches settle on the fine grid
    est_matched = int(np.count_nonzero(d_est <= d_v))
    gt_matched = int(np.count_nonzero(nearest_distances(gt, est, d_v / 4, max_distance=d_v) <= d_v))
    precision = est_matched / len(est) if len(est) else nan
    recall = gt_matched / len(gt) if len(gt) else nan
    if precision + recall > 0:
        f_score = 2 * precision * recall / (precision + recall)
    else:
        f_score = 0.0 if len(est) and len(gt) else nan
    return VoxelMetrics(
        paper_recall=est_matched / len(gt) if len(gt) else nan,
        paper_mse=float(d_est.mean()) if len(est) and len(gt) else nan,
        precision=precision,
        recall=recall,
        f_score=f_score,
        n_est=len(est),
        n_gt=len(gt),
    )


def map_voxel_metrics(
    est_map: "VoxelMap",
    gt_map: "VoxelMap",
    box_min: np.ndarray,
    box_max: np.ndarray,
    d_v: float = D_V,
    min_occupancy: float = _ABOVE_GT,
) -> VoxelMetrics:
    """``voxel_metrics`` on the voxels with occupancy >= ``min_occupancy`` of two maps in a box.

    The default keeps voxels strictly above 0.7, as the paper's V_est and V_GT.
    """
    est = est_map.voxels(box_min, box_max, min_occupancy=min_occupancy).centers
    gt = gt_map.voxels(box_min, box_max, min_occupancy=min_occupancy).centers
    return voxel_metrics(est, gt, d_v)

