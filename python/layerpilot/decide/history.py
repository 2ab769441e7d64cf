"""Path history H: where the drone has been recently, remembered between decision ticks."""

from __future__ import annotations

import numpy as np

from layerpilot.grid import GridGeometry


class PathHistory:
    """H starts at 1 everywhere; each tick zeroes cells within r_e of the drone, others regain n (cap 1).

    The grid may move or grow between ticks (the map window follows the map): cells the
    old and new grids share keep their value, new cells start at 1.
    """

    def __init__(self, r_e: float, n: float) -> None:
        self.r_e = float(r_e)
        self.n = np.float32(n)
        self.geometry: GridGeometry | None = None
        self.values: np.ndarray | None = None
        self.ticks = 0

    def on(self, geometry: GridGeometry) -> np.ndarray:
        """H on ``geometry`` (re-gridded if the grid changed), without ticking."""
        if geometry != self.geometry:
            self.values = self._regrid(geometry)
            self.geometry = geometry
        return self.values

    def tick(self, geometry: GridGeometry, distance: np.ndarray) -> np.ndarray:
        """One decision tick; ``distance`` = metres from the drone to each cell centre."""
        h = self.on(geometry)
        np.add(h, self.n, out=h)
        np.minimum(h, 1.0, out=h)
        h[distance < self.r_e] = 0.0
        self.ticks += 1
        return h

    def _regrid(self, geometry: GridGeometry) -> np.ndarray:
        new = np.ones(geometry.shape, np.float32)
        old, g = self.values, self.geometry
        if old is None or not np.isclose(g.resolution, geometry.resolution):
            return new
        res = geometry.resolution
        dc = int(round((g.origin_x - geometry.origin_x) / res))
        dr = int(round((g.origin_y - geometry.origin_y) / res))
        r0, c0 = max(dr, 0), max(dc, 0)
        r1, c1 = min(dr + g.height, geometry.height), min(dc + g.width, geometry.width)
        if r1 > r0 and c1 > c0:
            new[r0:r1, c0:c1] = old[r0 - dr:r1 - dr, c0 - dc:c1 - dc]
        return new
