"""Per-column summary of the voxel map: what the feature layers are built from."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from layerpilot.grid import GridGeometry


@dataclass(frozen=True)
class ColumnLayers:
    """One value per vertical column of a 2D window, about the column's highest occupied voxel.

    All arrays have ``geometry.shape`` (rows = y, columns = x; see ``GridGeometry``).
    Where ``observed`` is False the other arrays hold: elevation NaN, color 0,
    last_seen NaN, min_distance inf.
    """

    geometry: GridGeometry
    observed: np.ndarray  # bool: the column has a voxel above the occupied threshold
    elevation: np.ndarray  # float32 metres: top face of the highest such voxel
    color: np.ndarray  # uint8 (h, w, 3): its RGB
    last_seen: np.ndarray  # float64 mission-clock seconds: when it was last observed
    min_distance: np.ndarray  # float32 metres: closest it was ever observed from

    def __post_init__(self) -> None:
        h, w = self.geometry.shape
        expected = {
            "observed": ((h, w), np.bool_),
            "elevation": ((h, w), np.float32),
            "color": ((h, w, 3), np.uint8),
            "last_seen": ((h, w), np.float64),
            "min_distance": ((h, w), np.float32),
        }
        for name, (shape, dtype) in expected.items():
            arr = getattr(self, name)
            if arr.shape != shape or arr.dtype != dtype:
                raise ValueError(f"{name}: expected {shape} {np.dtype(dtype)}, got {arr.shape} {arr.dtype}")

    @classmethod
    def empty(cls, geometry: GridGeometry) -> "ColumnLayers":
        """An unobserved window (useful for tests and for regions the map has never seen)."""
        h, w = geometry.shape
        return cls(
            geometry,
            np.zeros((h, w), bool),
            np.full((h, w), np.nan, np.float32),
            np.zeros((h, w, 3), np.uint8),
            np.full((h, w), np.nan, np.float64),
            np.full((h, w), np.inf, np.float32),
        )
