"""FeatureLayers: named float32 layers in [0, 1] on one grid, plus what people look at (color, elevation)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from layerpilot.grid import GridGeometry, GridWindow
from layerpilot.layers import features


@dataclass(frozen=True)
class FeatureLayers:
    """Decision layers by name (float32 (h, w) in [0, 1]) with the grid they live on.

    ``observed`` (bool) and ``elevation_m`` (float32 metres, NaN unobserved) travel along
    because the decision needs coverage of the area of interest and terrain heights;
    ``rgb`` (uint8 (h, w, 3), the top voxel's color, 0 unobserved) is for pictures only and
    is never weighted; ``color`` gives it as float32 in [0, 1] when a picture needs it.
    ``window``: the layers cover only those cells (the decision computes no farther than it
    can choose); ``observed``, ``elevation_m`` and ``rgb`` always cover the whole grid.
    """

    geometry: GridGeometry
    layers: dict[str, np.ndarray]
    observed: np.ndarray
    elevation_m: np.ndarray
    rgb: np.ndarray
    now: float = 0.0
    window: GridWindow | None = None

    def __post_init__(self) -> None:
        shape = self.geometry.shape
        if self.window is not None and not GridWindow.full(self.geometry).contains(self.window):
            raise ValueError(f"window: {self.window} does not lie within the grid {self.geometry}")
        for name, arr in self.layers.items():
            check_layer(name, arr, shape if self.window is None else self.window.shape)
        for name, arr, want, dtype in (
            ("observed", self.observed, shape, np.bool_),
            ("elevation_m", self.elevation_m, shape, np.float32),
            ("rgb", self.rgb, (*shape, 3), np.uint8),
        ):
            if arr.shape != want or arr.dtype != dtype:
                raise ValueError(f"{name}: expected {want} {np.dtype(dtype)}, got {arr.shape} {arr.dtype}")

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.layers[name]
        except KeyError:
            raise KeyError(f"no layer named {name!r} in this layer set; have: {', '.join(self.layers)}") from None

    @cached_property
    def color(self) -> np.ndarray:
        """The color layer: float32 (h, w, 3) in [0, 1], black where unobserved."""
        return features.color(self.observed, self.rgb)

    @property
    def names(self) -> list[str]:
        return list(self.layers)


def check_layer(name: str, arr: object, shape: tuple[int, int]) -> np.ndarray:
    """ValueError naming the layer unless ``arr`` is float32 of ``shape`` with every value in [0, 1]."""
    if not isinstance(arr, np.ndarray) or arr.shape != shape or arr.dtype != np.float32:
        got = f"{arr.shape} {arr.dtype}" if isinstance(arr, np.ndarray) else type(arr).__name__
        raise ValueError(f"layer {name!r}: expected float32 array of shape {shape}, got {got}")
    if arr.size == 0:  # an empty window: the drone is beyond the grid (the maker then heads for the area)
        return arr
    lo, hi = float(arr.min()), float(arr.max())
    if not (lo >= 0.0 and hi <= 1.0):  # also catches NaN
        raise ValueError(f"layer {name!r}: values must lie in [0, 1], got [{lo}, {hi}]")
    return arr
