"""Per-column summary of the voxel map: what the feature layers are built from."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from layerpilot.grid import GridGeometry, GridWindow

RANGED = ("elevation", "last_seen")  # the arrays the layers scale over the whole grid's observed columns


@dataclass(frozen=True)
class ColumnLayers:
    """One value per vertical column of a 2D window, about the column's highest occupied voxel.

    All arrays have ``geometry.shape`` (rows = y, columns = x; see ``GridGeometry``).
    Where ``observed`` is False the other arrays hold: elevation NaN, color 0,
    last_seen NaN, min_distance inf.

    ``window`` (a drone's neighbourhood, as a large survey's layer sets carry it): only
    ``observed`` covers the whole grid; the other arrays hold values only in the window
    and read as unobserved outside it, and ``ranges`` gives, per name in ``RANGED``, the
    (min, max) over the whole grid's observed columns that the layers are scaled by.
    """

    geometry: GridGeometry
    observed: np.ndarray  # bool: the column has a voxel above the occupied threshold
    elevation: np.ndarray  # float32 metres: top face of the highest such voxel
    color: np.ndarray  # uint8 (h, w, 3): its RGB
    last_seen: np.ndarray  # float64 mission-clock seconds: when it was last observed
    min_distance: np.ndarray  # float32 metres: closest it was ever observed from
    window: GridWindow | None = None
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict, compare=False)

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
        if self.window is not None and not GridWindow.full(self.geometry).contains(self.window):
            raise ValueError(f"window: {self.window} does not lie within the grid {self.geometry}")

    def value_range(self, name: str) -> tuple[float, float] | None:
        """(min, max) of a ``RANGED`` array over the whole grid's observed columns; None if none has a value."""
        if self.window is not None:
            return self.ranges.get(name)
        return observed_range(getattr(self, name), self.observed)

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


def observed_range(values: np.ndarray, observed: np.ndarray) -> tuple[float, float] | None:
    """(min, max) of the finite values of observed cells; None if there are none.

    Unobserved columns hold NaN (``ColumnLayers``' contract), so a NaN-ignoring reduction
    over the whole array, one fast pass, finds them; only if it meets an infinity (not a
    valid value) is the slower masked reduction needed.
    """
    lo, hi = float(np.fmin.reduce(values, axis=None)), float(np.fmax.reduce(values, axis=None))
    if np.isfinite(lo) and np.isfinite(hi):
        return lo, hi
    valid = observed & np.isfinite(values)
    if not valid.any():
        return None
    return float(np.min(values, where=valid, initial=np.inf)), float(np.max(values, where=valid, initial=-np.inf))
