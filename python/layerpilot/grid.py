"""Geometry of a 2D column grid in the map frame (ENU metres).

Arrays on a grid have shape (height, width); row j, column i is the cell whose
centre is (origin_x + (i + 0.5) * resolution, origin_y + (j + 0.5) * resolution).
Row 0 is the southern-most row (smallest y); pictures flip it to the top.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GridGeometry:
    origin_x: float
    origin_y: float
    resolution: float
    width: int
    height: int

    def __post_init__(self) -> None:
        if not self.resolution > 0:
            raise ValueError(f"resolution must be > 0, got {self.resolution}")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"width and height must be > 0, got {self.width}x{self.height}")

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the grid's outer edges, for plotting."""
        return (
            self.origin_x,
            self.origin_x + self.width * self.resolution,
            self.origin_y,
            self.origin_y + self.height * self.resolution,
        )

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """x and y of every cell centre, each of shape (height, width)."""
        xs = self.origin_x + (np.arange(self.width) + 0.5) * self.resolution
        ys = self.origin_y + (np.arange(self.height) + 0.5) * self.resolution
        return np.meshgrid(xs, ys)

    def cell_center(self, row: int, col: int) -> tuple[float, float]:
        return (
            self.origin_x + (col + 0.5) * self.resolution,
            self.origin_y + (row + 0.5) * self.resolution,
        )

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the cell containing the point; may lie outside the grid."""
        return (
            int(np.floor((y - self.origin_y) / self.resolution)),
            int(np.floor((x - self.origin_x) / self.resolution)),
        )

    def contains(self, row: int, col: int) -> bool:
        return 0 <= row < self.height and 0 <= col < self.width

    @classmethod
    def centered(cls, x: float, y: float, resolution: float, width: int, height: int) -> "GridGeometry":
        """A grid of width x height cells centred on (x, y), aligned to the resolution."""
        ox = np.floor(x / resolution - width / 2) * resolution
        oy = np.floor(y / resolution - height / 2) * resolution
        return cls(float(ox), float(oy), resolution, width, height)


@dataclass(frozen=True)
class GridWindow:
    """A rectangle of cells of a grid: rows [row0, row1), columns [col0, col1) (may be empty).

    Work that only matters near the drone (the decision looks no farther than r_i) runs on
    a window instead of the whole grid; a rectangle keeps row-major order, so an argmax
    over the window visits cells in the same order as one over the grid.
    """

    row0: int
    row1: int
    col0: int
    col1: int

    def __post_init__(self) -> None:
        if not (0 <= self.row0 <= self.row1 and 0 <= self.col0 <= self.col1):
            raise ValueError(f"window: expected 0 <= row0 <= row1 and 0 <= col0 <= col1, got {self}")

    @classmethod
    def full(cls, geometry: GridGeometry) -> "GridWindow":
        return cls(0, geometry.height, 0, geometry.width)

    @classmethod
    def around(cls, geometry: GridGeometry, x: float, y: float, radius: float) -> "GridWindow":
        """Every cell whose centre may lie within ``radius`` of (x, y), clipped to the grid.

        One cell of slack on each side, so float32 distances rounding down cannot put a
        cell inside the radius that the window left out.
        """
        r0, c0 = geometry.cell_of(x - radius, y - radius)
        r1, c1 = geometry.cell_of(x + radius, y + radius)
        return cls(*_clip(r0 - 1, r1 + 2, geometry.height), *_clip(c0 - 1, c1 + 2, geometry.width))

    @property
    def shape(self) -> tuple[int, int]:
        return (self.row1 - self.row0, self.col1 - self.col0)

    @property
    def slices(self) -> tuple[slice, slice]:
        return (slice(self.row0, self.row1), slice(self.col0, self.col1))

    @property
    def empty(self) -> bool:
        return self.row1 == self.row0 or self.col1 == self.col0

    def contains(self, other: "GridWindow") -> bool:
        return (self.row0 <= other.row0 and other.row1 <= self.row1
                and self.col0 <= other.col0 and other.col1 <= self.col1)

    def union(self, other: "GridWindow") -> "GridWindow":
        if other.empty:
            return self
        if self.empty:
            return other
        return GridWindow(min(self.row0, other.row0), max(self.row1, other.row1),
                          min(self.col0, other.col0), max(self.col1, other.col1))

    def grown(self, cells: int, geometry: GridGeometry) -> "GridWindow":
        """``cells`` more on every side, clipped to the grid."""
        return GridWindow(*_clip(self.row0 - cells, self.row1 + cells, geometry.height),
                          *_clip(self.col0 - cells, self.col1 + cells, geometry.width))

    def within(self, outer: "GridWindow") -> tuple[slice, slice]:
        """This window's cells as slices of an array covering ``outer`` (which must contain it)."""
        if not outer.contains(self):
            raise ValueError(f"window: {self} does not lie within {outer}")
        return (slice(self.row0 - outer.row0, self.row1 - outer.row0),
                slice(self.col0 - outer.col0, self.col1 - outer.col0))


def _clip(lo: int, hi: int, size: int) -> tuple[int, int]:
    lo, hi = min(max(lo, 0), size), min(max(hi, 0), size)
    return lo, max(lo, hi)
