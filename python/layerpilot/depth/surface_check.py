"""The surface check: a cloud whose surface jumps metres away from the surface of the clouds just before
it is refused, not put in the map.

Consecutive frames a second apart see mostly the same ground and trees, and the sensor errors that move
a whole cloud (GNSS's wander, the barometer's drift) change by decimetres in that time. A cloud whose
surface lies metres above or below the recent clouds' over the cells they share has a wrong pose or a
wrong scale (a pair whose baseline the images and GNSS got wrong together passes every pair check, and
its points land metres off: docs/eval.md, "Real sensors"). Each cloud's surface is its highest point
per ``cell`` in plan; the reference is, per cell, the median height of every cloud of the last
``memory`` seconds (refused ones too), and the jump is the median difference over the cells a cloud
shares with it. Beyond ``max_jump`` the cloud is refused and counted; with fewer than ``min_cells``
shared cells (the first cloud, new ground) there is nothing to compare and it is accepted. A median
over every recent view, not over the accepted ones only, keeps one wrong cloud that got in (over new
ground) from locking out the good ones after it, and takes a lasting shift of the whole flight (a GNSS
jump) as soon as most recent clouds share it.

The same jumps say how consistent the map is while no truth is at hand: the median ``|jump|`` of the last
``consistency_clouds`` compared clouds (``surface_jump_median_m``). Beyond ``warn_median_jump`` the check
warns once (log) and counts every cloud it accepts meanwhile (``surface_accepted_inconsistent``): sensors
worse than the depth settings assume are said, not mapped in silence. On ``demo --config consumer``
(world 0, the only one measured) this median stays under 0.5 m with ``rtk`` sensors and under 1.4 m with
``consumer``, while with ``degraded``, whose map is metres off, it is over 1.5 m for 60 % of the clouds.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass

import numpy as np

from layerpilot.config import check_range
from layerpilot.geometry import PointCloud

_log = logging.getLogger("layerpilot.depth")


@dataclass(frozen=True)
class SurfaceCheckConfig:
    """The defaults are the measured ones of docs/depth.md."""

    cell: float = 1.0  # m: the surface is the highest point per cell of this side
    memory: float = 10.0  # s: clouds accepted this long before a cloud are its reference
    max_jump: float = 2.0  # m: a larger median height difference from the reference refuses the cloud
    min_cells: int = 200  # shared cells needed to compare
    consistency_clouds: int = 60  # compared clouds whose median |jump| is the map's consistency
    warn_median_jump: float = 1.5  # m: a larger median |jump| warns and counts the clouds accepted meanwhile

    def __post_init__(self) -> None:
        check_range("surface_check.cell", self.cell, 1e-3)
        check_range("surface_check.memory", self.memory, 0.0)
        check_range("surface_check.max_jump", self.max_jump, 1e-3)
        check_range("surface_check.min_cells", self.min_cells, 1)
        check_range("surface_check.consistency_clouds", self.consistency_clouds, 1)
        check_range("surface_check.warn_median_jump", self.warn_median_jump, 1e-3)


def surface(points: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """The highest point per plan cell: (sorted unique int64 cell keys, their heights)."""
    ij = np.floor(np.asarray(points[:, :2], np.float64) / cell).astype(np.int64) + (1 << 31)
    keys = (ij[:, 0] << 32) | ij[:, 1]
    order = np.argsort(keys)  # one key, then the highest of each run: twice as fast as sorting by key and z
    keys = keys[order]
    start = np.flatnonzero(np.r_[len(keys) > 0, keys[1:] != keys[:-1]])
    return keys[start], np.maximum.reduceat(np.asarray(points[order, 2], np.float64), start)


def _cell_medians(keys: np.ndarray, heights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell key, the (lower) median of its heights: (sorted unique keys, medians)."""
    order = np.lexsort((heights, keys))
    keys, heights = keys[order], heights[order]
    unique, start, count = np.unique(keys, return_index=True, return_counts=True)
    return unique, heights[start + (count - 1) // 2]


class SurfaceCheck:
    """Compares each cloud's surface with the recent clouds' per-cell median."""

    def __init__(self, config: SurfaceCheckConfig = SurfaceCheckConfig()) -> None:
        self.config = config
        self._recent: deque[tuple[float, np.ndarray, np.ndarray]] = deque()  # (stamp, keys, heights), oldest first
        self.checked = self.refused = self.inconsistent = 0
        self.last_jump = float("nan")  # m, the newest cloud's median height difference (NaN: not compared)
        self._jumps: deque[float] = deque(maxlen=config.consistency_clouds)  # |jump| of the last compared clouds
        self._warned = False

    def accepts(self, cloud: PointCloud, lift: float = 0.0) -> bool:
        """True if ``cloud``, raised by ``lift`` metres (the height correction it is about to get), agrees with
        the recent surface (or there is none to compare); either way it joins the reference."""
        c = self.config
        while self._recent and self._recent[0][0] < cloud.stamp - c.memory:
            self._recent.popleft()
        keys, heights = surface(cloud.points, c.cell)
        heights += lift
        jump = self._jump(keys, heights)
        self.last_jump = jump
        ok = not (np.isfinite(jump) and abs(jump) > c.max_jump)
        if np.isfinite(jump):
            self.checked += 1
            self.refused += not ok
            self._jumps.append(abs(jump))
            if ok and self.median_jump > c.warn_median_jump:
                self.inconsistent += 1
                if not self._warned:
                    self._warned = True
                    _log.warning("clouds disagree by a median %.1f m over the last %d: the map's geometry is metres "
                                 "off (sensors worse than the depth settings assume); counted in "
                                 "surface_accepted_inconsistent", self.median_jump, len(self._jumps))
        self._recent.append((cloud.stamp, keys, heights))  # refused too: the reference is every recent view
        return ok

    def _jump(self, keys: np.ndarray, heights: np.ndarray) -> float:
        """Median height difference from the recent surface (per cell, the median of the recent clouds'
        heights); NaN if too few cells are shared."""
        if not self._recent:
            return float("nan")
        ref_keys, ref_heights = _cell_medians(np.concatenate([k for _, k, _ in self._recent]),
                                              np.concatenate([h for _, _, h in self._recent]))
        _, mine, theirs = np.intersect1d(keys, ref_keys, assume_unique=True, return_indices=True)
        if len(mine) < self.config.min_cells:
            return float("nan")
        return float(np.median(heights[mine] - ref_heights[theirs]))

    @property
    def median_jump(self) -> float:
        """m: the median |jump| of the last compared clouds (NaN before the first)."""
        return float(np.median(self._jumps)) if self._jumps else float("nan")

    def stats(self) -> dict[str, float]:
        jump = {"surface_jump_median_m": round(self.median_jump, 3)} if self._jumps else {}
        return {"surface_checked": self.checked, "surface_refused": self.refused, **jump,
                "surface_accepted_inconsistent": self.inconsistent}
