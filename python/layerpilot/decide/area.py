"""Area of interest Z as a 0/1 mask on a grid, and the grid that covers it."""

from __future__ import annotations

import numpy as np

from layerpilot.decide.behavior import Area
from layerpilot.grid import GridGeometry


def zone_mask(area: Area, geometry: GridGeometry, home: tuple[float, float]) -> np.ndarray:
    """float32 1 where the cell centre lies inside the area, 0 outside."""
    x, y = geometry.cell_centers()
    if area.shape == "circle":
        cx, cy = area.center if area.center is not None else home
        inside = (x - cx) ** 2 + (y - cy) ** 2 <= area.radius**2
    else:
        inside = _inside_polygon(x, y, np.asarray(area.polygon, np.float64))
    return inside.astype(np.float32)


def _inside_polygon(x: np.ndarray, y: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule over the polygon's edges, vectorised over cells (exact for cell centres)."""
    inside = np.zeros(x.shape, bool)
    for (x0, y0), (x1, y1) in zip(poly, np.roll(poly, -1, axis=0)):
        if y0 == y1:
            continue
        crosses = (y0 > y) != (y1 > y)
        x_at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (x < x_at)
    return inside


def area_bounds(area: Area, home: tuple[float, float]) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) of the area in the map frame."""
    if area.shape == "circle":
        cx, cy = area.center if area.center is not None else home
        return cx - area.radius, cx + area.radius, cy - area.radius, cy + area.radius
    p = np.asarray(area.polygon, np.float64)
    return float(p[:, 0].min()), float(p[:, 0].max()), float(p[:, 1].min()), float(p[:, 1].max())


def area_geometry(area: Area, home: tuple[float, float], resolution: float = 1.0, margin: float = 20.0) -> GridGeometry:
    """The grid (aligned to ``resolution``) covering the area plus ``margin`` metres all round.

    The margin lets the fringe see just past the area's edge, so its frontier is not the
    window border.
    """
    xmin, xmax, ymin, ymax = area_bounds(area, home)
    ox = np.floor((xmin - margin) / resolution) * resolution
    oy = np.floor((ymin - margin) / resolution) * resolution
    w = int(np.ceil((xmax + margin - ox) / resolution))
    h = int(np.ceil((ymax + margin - oy) / resolution))
    return GridGeometry(float(ox), float(oy), resolution, w, h)
