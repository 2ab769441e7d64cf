"""Path history H: where the drone has been recently, remembered between decision ticks."""

from __future__ import annotations

import numpy as np

from layerpilot.grid import GridGeometry, GridWindow

_NEVER = np.iinfo(np.int32).min  # a cell the drone has not been near: H = 1


class PathHistory:
    """H starts at 1 everywhere; each tick zeroes cells within r_e of the drone, others regain n (cap 1).

    The grid may move or grow between ticks (the map window follows the map): cells the
    old and new grids share keep their value, new cells start at 1.

    Stored lazily, so a tick costs the cells near the drone and not the grid: per cell the
    tick it was last zeroed, and one table of what repeated float32 additions of n give,
    ``_table[k]`` = H k ticks after zeroing (0, n, n + n, ... capped at 1). A cell's H is
    the table entry for its age: the same float32 values as adding n to every cell every tick.
    """

    def __init__(self, r_e: float, n: float) -> None:
        if not r_e >= 0 or not 0 <= n <= 1:
            raise ValueError(f"path history: expected r_e >= 0 and n in [0, 1], got r_e = {r_e}, n = {n}")
        self.r_e = float(r_e)
        self.n = np.float32(n)
        self.geometry: GridGeometry | None = None
        self.zeroed: np.ndarray | None = None  # int32 tick each cell was last zeroed (_NEVER: not yet)
        self.ticks = 0
        self._table = np.zeros(1, np.float32)

    @property
    def values(self) -> np.ndarray | None:
        """H on the whole current grid (float32), or None before the first tick or ``on``."""
        return None if self.geometry is None else self._lookup(self.zeroed)

    def on(self, geometry: GridGeometry, window: GridWindow | None = None) -> np.ndarray:
        """H on ``geometry`` (re-gridded if the grid changed), without ticking; ``window``: those cells only."""
        self._follow(geometry)
        return self._lookup(self.zeroed if window is None else self.zeroed[window.slices])

    def tick(self, geometry: GridGeometry, distance: np.ndarray, window: GridWindow | None = None) -> np.ndarray:
        """One decision tick; ``distance`` = metres from the drone to each cell centre (of ``window``).

        Only cells of ``window`` can be zeroed, so it must hold every cell within r_e.
        """
        self._follow(geometry)
        self.ticks += 1
        self._extend()
        zeroed = self.zeroed if window is None else self.zeroed[window.slices]
        if distance.shape != zeroed.shape:
            raise ValueError(f"distance: expected shape {zeroed.shape}, got {distance.shape}")
        zeroed[distance < self.r_e] = self.ticks
        return self._lookup(zeroed)

    def _follow(self, geometry: GridGeometry) -> None:
        if geometry != self.geometry:
            self.zeroed = self._regrid(geometry)
            self.geometry = geometry

    def _extend(self) -> None:
        """One more table entry per tick, until H reaches 1 (or n no longer moves it)."""
        last = self._table[-1]
        nxt = min(np.float32(last + self.n), np.float32(1.0))
        if nxt != last:
            self._table = np.append(self._table, np.float32(nxt))

    def _lookup(self, zeroed: np.ndarray) -> np.ndarray:
        age = np.int64(self.ticks) - zeroed
        np.minimum(age, len(self._table) - 1, out=age)
        h = self._table[age]
        h[zeroed == _NEVER] = 1.0
        return h

    def _regrid(self, geometry: GridGeometry) -> np.ndarray:
        new = np.full(geometry.shape, _NEVER, np.int32)
        old, g = self.zeroed, self.geometry
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
