"""Terrain-aware altitude: clear the highest column top near the straight path to the waypoint."""

from __future__ import annotations

import numpy as np

from layerpilot.decide.behavior import Terrain
from layerpilot.grid import GridGeometry


def terrain_altitude(
    elevation: np.ndarray,
    geometry: GridGeometry,
    start: tuple[float, float],
    end: tuple[float, float],
    terrain: Terrain,
    default: float,
) -> float:
    """max(elevation within ``corridor`` of the segment) + clearance, clipped to the limits.

    Unobserved columns (NaN) are ignored; with nothing observed near the path the
    behavior's mission altitude is used (still clipped to the limits).
    """
    (sx, sy), (ex, ey) = start, end
    pad = terrain.corridor + geometry.resolution
    r0, c0 = geometry.cell_of(min(sx, ex) - pad, min(sy, ey) - pad)
    r1, c1 = geometry.cell_of(max(sx, ex) + pad, max(sy, ey) + pad)
    r0, c0 = max(r0, 0), max(c0, 0)
    r1, c1 = min(r1 + 1, geometry.height), min(c1 + 1, geometry.width)
    top = None
    if r1 > r0 and c1 > c0:
        res = geometry.resolution
        xs = geometry.origin_x + (np.arange(c0, c1) + 0.5) * res
        ys = geometry.origin_y + (np.arange(r0, r1) + 0.5) * res
        px, py = xs[None, :] - sx, ys[:, None] - sy
        dx, dy = ex - sx, ey - sy
        t = np.clip((px * dx + py * dy) / max(dx * dx + dy * dy, 1e-12), 0.0, 1.0)
        near = np.hypot(px - t * dx, py - t * dy) <= terrain.corridor + 0.5 * res * np.sqrt(2)
        window = elevation[r0:r1, c0:c1]
        heights = window[near & np.isfinite(window)]
        if heights.size:
            top = float(heights.max())
    z = default if top is None else top + terrain.clearance
    return float(np.clip(z, terrain.min_altitude, terrain.max_altitude))
