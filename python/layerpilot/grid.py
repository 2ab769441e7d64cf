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
