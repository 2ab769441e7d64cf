"""Height registration: each new cloud is lifted or lowered onto the ground and trees the flight has
already mapped, so the map keeps one height while GNSS's vertical error wanders.

The sliding window (``depth.window``) takes the trajectory's shape from the images but its place from
GNSS, whose vertical error is the largest a consumer drone has (metres, wandering over minutes, plus
the barometer's drift): two passes over the same trees minutes apart land metres apart in height and
the map smears. Here each cloud, once placed, is compared with a local map of the earlier clouds'
points (one per voxel, the first kept): for every sampled point, the nearest map point in plan within
``max_plan_distance``; the median height difference (within ``max_residual``) is the correction's step,
taken when at least ``min_matches`` points agree and the step is no more than ``max_step`` (else the
last correction stays and the reason is counted). The correction is a single vertical shift, applied to
the cloud, its origin and the camera pose the trajectory reports; horizontally GNSS's error stays
within the map's match distance and is left alone (a full rigid registration was measured to move the
map horizontally more than it fixed: docs/depth.md).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from layerpilot.config import check_range
from layerpilot.geometry import PointCloud, Pose

SKIPS = ("first_cloud", "too_few_matches", "step_too_large")


@dataclass(frozen=True)
class HeightRegistrationConfig:
    """The local map's density and the fit's limits; the defaults are the measured ones of docs/depth.md."""

    map_voxel: float = 1.0  # m: the local map keeps one point per voxel of this size
    sample_voxel: float = 1.5  # m: a cloud is compared with one point per voxel of this size
    radius: float = 200.0  # m: map tiles farther than this in plan from the newest cloud's origin leave
    tile: float = 32.0  # m: the local map is kept in square tiles of this side (what a cloud is compared with)
    max_plan_distance: float = 1.0  # m: a sampled point's map neighbour must be this close in plan
    max_residual: float = 4.0  # m: height differences beyond this are not the same surface
    min_matches: int = 200
    max_step: float = 1.0  # m: a larger step from the last correction is distrusted

    def __post_init__(self) -> None:
        for name in ("map_voxel", "sample_voxel", "radius", "tile", "max_plan_distance", "max_residual", "max_step"):
            check_range(f"height_registration.{name}", getattr(self, name), 1e-3)
        check_range("height_registration.min_matches", self.min_matches, 1)


def _voxel_keys(points: np.ndarray, voxel: float) -> np.ndarray:
    """One int64 per voxel of side ``voxel`` (21 bits an axis: +-1,048,576 voxels)."""
    k = np.floor(points / voxel).astype(np.int64) + (1 << 20)
    return (k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2]


class HeightRegistration:
    """Keeps one vertical correction for a camera's clouds, fitted to the clouds before them."""

    def __init__(self, config: HeightRegistrationConfig = HeightRegistrationConfig()) -> None:
        self.config = config
        self.correction = 0.0  # m, added to every height of the newest cloud
        self._tiles: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}  # tile -> (points, voxel keys)
        self._keys: set[int] = set()
        self._stamps: list[float] = []
        self._corrections: list[float] = []
        self.registered = 0
        self.skipped: Counter[str] = Counter()

    def register(self, cloud: PointCloud) -> PointCloud:
        """The cloud at the flight's height, fitted to the local map, which then takes its points."""
        c = self.config
        points = cloud.points.astype(np.float64)
        keys = _voxel_keys(points, c.sample_voxel)
        _, first = np.unique(keys, return_index=True)
        sample = points[np.sort(first)]
        sample[:, 2] += self.correction
        step, reason = self._step(sample)
        if step is None:
            self.skipped[reason] += 1
        else:
            self.correction += step
            sample[:, 2] += step
            self.registered += 1
        self._stamps.append(cloud.stamp)
        self._corrections.append(self.correction)
        origin = cloud.origin + (0.0, 0.0, self.correction)
        self._add(sample, origin)
        points[:, 2] += self.correction
        return PointCloud(points.astype(np.float32), origin, cloud.stamp, cloud.colors)

    def _near(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The local map's points in the tiles that the box lo..hi (plan) touches."""
        t0, t1 = np.floor(lo[:2] / self.config.tile).astype(int), np.floor(hi[:2] / self.config.tile).astype(int)
        parts = [self._tiles[(i, j)][0] for i in range(t0[0], t1[0] + 1) for j in range(t0[1], t1[1] + 1)
                 if (i, j) in self._tiles]
        return np.vstack(parts) if parts else np.zeros((0, 3))

    def _step(self, sample: np.ndarray) -> tuple[float | None, str]:
        c = self.config
        if not self._tiles:
            return None, "first_cloud"
        near = self._near(sample.min(0) - c.max_plan_distance, sample.max(0) + c.max_plan_distance)
        if len(near) < c.min_matches:
            return None, "too_few_matches"
        d, idx = cKDTree(near[:, :2]).query(sample[:, :2], distance_upper_bound=c.max_plan_distance)
        found = np.isfinite(d)
        dz = near[idx[found], 2] - sample[found, 2]
        dz = dz[np.abs(dz) < c.max_residual]
        if len(dz) < c.min_matches:
            return None, "too_few_matches"
        step = float(np.median(dz))
        if abs(step) > c.max_step:
            return None, "step_too_large"
        return step, "ok"

    def _add(self, points: np.ndarray, origin: np.ndarray) -> None:
        """New voxels' points into their tiles; tiles beyond ``radius`` in plan leave the map."""
        c = self.config
        keys = _voxel_keys(points, c.map_voxel)
        new = np.fromiter((k not in self._keys for k in keys.tolist()), bool, len(keys))
        points, keys = points[new], keys[new]
        self._keys.update(keys.tolist())
        tiles = np.floor(points[:, :2] / c.tile).astype(int)
        for t in {tuple(t) for t in tiles.tolist()}:
            mine = np.all(tiles == t, axis=1)
            old_points, old_keys = self._tiles.get(t, (np.zeros((0, 3)), np.zeros(0, np.int64)))
            self._tiles[t] = (np.vstack([old_points, points[mine]]), np.concatenate([old_keys, keys[mine]]))
        for t in [t for t in self._tiles if math.hypot((t[0] + 0.5) * c.tile - origin[0],
                                                       (t[1] + 0.5) * c.tile - origin[1]) > c.radius + c.tile]:
            self._keys.difference_update(self._tiles.pop(t)[1].tolist())

    @property
    def map_points(self) -> int:
        return sum(len(p) for p, _ in self._tiles.values())

    def corrected(self, trajectory: list[tuple[float, Pose]]) -> list[tuple[float, Pose]]:
        """Camera poses lifted by the correction of the cloud nearest in time: where the clouds show them."""
        if not self._stamps or not trajectory:
            return trajectory
        stamps = np.asarray(self._stamps)  # in order: clouds come in time order
        t = np.array([stamp for stamp, _ in trajectory])
        after = np.clip(np.searchsorted(stamps, t), 0, len(stamps) - 1)
        before = np.maximum(after - 1, 0)
        nearest = np.where(np.abs(stamps[before] - t) <= np.abs(stamps[after] - t), before, after)
        return [(stamp, Pose(pose.position + (0.0, 0.0, self._corrections[i]), pose.orientation))
                for (stamp, pose), i in zip(trajectory, nearest.tolist())]

    def stats(self) -> dict[str, float]:
        return {"height_registered": self.registered,
                **{f"height_skipped_{k}": self.skipped[k] for k in SKIPS},
                "height_correction_m": round(self.correction, 3), "height_map_points": self.map_points}
