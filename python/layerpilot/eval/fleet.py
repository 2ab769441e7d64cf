"""What a fleet's drones did together: how close they came and how much of the area they saw twice.

A drone "saw" a column of the area when a point of one of its clouds fell in it. Duplicate coverage is
the share of the area's seen columns that two or more drones saw by a given time (the fleet's time to
90 % of the area): work done twice while there was still work to share. Separation: the
smallest horizontal distance between two drones' true positions over the scored flight, and the
smallest height difference at any moment two drones were horizontally nearer than ``separation`` (their
altitude layers keep them apart there).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np

from layerpilot.grid import GridGeometry


class FleetTracker:
    """Per-drone coverage masks over a mission's grid and the closest approach between any two drones."""

    def __init__(self, geometry: GridGeometry, aoi: np.ndarray, vehicles: Sequence[str],
                 separation: float = 10.0) -> None:
        if aoi.shape != geometry.shape:
            raise ValueError(f"aoi: shape {aoi.shape} is not the grid's {geometry.shape}")
        self.geometry, self.aoi, self.vehicles, self.separation = geometry, aoi, tuple(vehicles), separation
        self._first = {v: np.full(geometry.shape, np.inf) for v in self.vehicles}  # when each drone first saw a column
        self.min_separation = math.inf
        self.closest: tuple[float, str, str] | None = None  # (time, vehicle, vehicle) of the closest approach
        self.min_gap_near = math.inf  # m of height between two drones horizontally nearer than ``separation``

    def positions(self, t: float, where: Mapping[str, Sequence[float]]) -> None:
        """The drones' true positions (x, y, z) at mission time ``t`` (map frame)."""
        for a, b in itertools.combinations(self.vehicles, 2):
            d = math.hypot(where[a][0] - where[b][0], where[a][1] - where[b][1])
            if d < self.min_separation:
                self.min_separation, self.closest = d, (t, a, b)
            if d < self.separation:
                self.min_gap_near = min(self.min_gap_near, abs(where[a][2] - where[b][2]))

    def saw(self, vehicle: str, points: np.ndarray, t: float) -> None:
        """The columns a cloud of ``vehicle``'s (N x 3, map frame) taken at mission time ``t`` fell in."""
        g = self.geometry
        cols = np.floor((points[:, 0] - g.origin_x) / g.resolution).astype(np.int64)
        rows = np.floor((points[:, 1] - g.origin_y) / g.resolution).astype(np.int64)
        inside = (cols >= 0) & (cols < g.width) & (rows >= 0) & (rows < g.height)
        first = self._first[vehicle]
        rows, cols = rows[inside], cols[inside]
        first[rows, cols] = np.minimum(first[rows, cols], t)

    def metrics(self, until: float = math.inf) -> dict[str, float]:
        """``fleet_min_separation_m`` (NaN for one drone), ``fleet_min_height_gap_near_m``,
        ``fleet_duplicate_coverage`` (0..1, of the columns seen by ``until``) and each drone's share of the
        area seen over the whole flight (``seen_<vehicle>``, %)."""
        count = sum((np.isfinite(f) & (f <= until)).astype(np.int32) for f in self._first.values())
        seen = np.count_nonzero((count >= 1) & self.aoi)
        twice = np.count_nonzero((count >= 2) & self.aoi)
        area = max(np.count_nonzero(self.aoi), 1)
        out = {"fleet_min_separation_m": float(self.min_separation) if self.closest else math.nan,
               "fleet_min_height_gap_near_m": float(self.min_gap_near) if math.isfinite(self.min_gap_near)
               else math.nan,  # NaN: never horizontally nearer than the separation
               "fleet_duplicate_coverage": float(twice / seen) if seen else 0.0}
        out.update({f"seen_{v}": float(100.0 * np.count_nonzero(np.isfinite(f) & self.aoi) / area)
                    for v, f in self._first.items()})
        return out
