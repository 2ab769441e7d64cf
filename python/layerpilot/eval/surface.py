"""A reference surface from a LAS/LAZ point cloud, in the map frame, to score photo maps against.

The cloud is put into the map frame through geodesy: its CRS (from the LAS header, or the
origin's UTM zone when the header has none) -> WGS 84 -> the map's ``LocalFrame``; heights pass
through unchanged (the reference and EXIF GPS altitudes must share a vertical datum; no shift
is estimated). The surface is the top of the cloud: the highest point per ``cell`` (0.25 m).
The distance of a point to it is the shortest distance to the top of a cell within ``radius``
horizontally; points over cells the reference does not cover are not scored.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from pyproj import Transformer

from layerpilot.geodesy import WGS84, LocalFrame
from layerpilot.grid import GridGeometry


@dataclass(frozen=True)
class ReferenceSurface:
    origin: np.ndarray  # (2,) map-frame x, y of the grid's south-west corner
    cell: float
    top: np.ndarray  # (nx, ny) highest z per cell, NaN = no point

    @classmethod
    def from_points(cls, points: np.ndarray, cell: float = 0.25) -> "ReferenceSurface":
        points = np.asarray(points, np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or not len(points):
            raise ValueError(f"points: expected a non-empty (N, 3) array, got {points.shape}")
        lo = points[:, :2].min(0)
        ij = np.floor((points[:, :2] - lo) / cell).astype(np.int64)
        top = np.full(tuple(ij.max(0) + 1), -np.inf)
        np.maximum.at(top, (ij[:, 0], ij[:, 1]), points[:, 2])
        top[np.isinf(top)] = np.nan
        return cls(lo, cell, top)

    def _cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        ij = np.floor((np.asarray(xy, np.float64) - self.origin) / self.cell).astype(np.int64)
        inside = (ij >= 0).all(1) & (ij[:, 0] < self.top.shape[0]) & (ij[:, 1] < self.top.shape[1])
        return ij[:, 0], ij[:, 1], inside

    def covers(self, points: np.ndarray, radius: float = 0.5) -> np.ndarray:
        """True where a reference cell with a point lies within ``radius`` of the point's column."""
        r = int(np.ceil(radius / self.cell))
        known = cv2.dilate((~np.isnan(self.top)).astype(np.uint8), np.ones((2 * r + 1, 2 * r + 1), np.uint8)) > 0
        i, j, inside = self._cells(np.asarray(points)[:, :2])
        out = np.zeros(len(i), bool)
        out[inside] = known[i[inside], j[inside]]
        return out

    def distance(self, points: np.ndarray, radius: float = 1.0) -> np.ndarray:
        """Distance (m) of each point to the surface searched within ``radius``; inf if none there."""
        p = np.asarray(points, np.float64)
        i, j, _ = self._cells(p[:, :2])
        r = int(np.ceil(radius / self.cell))
        best = np.full(len(p), np.inf)
        for di in range(-r, r + 1):
            for dj in range(-r, r + 1):
                h = float(np.hypot(di, dj)) * self.cell
                if h > radius:
                    continue
                ii, jj = i + di, j + dj
                ok = (ii >= 0) & (jj >= 0) & (ii < self.top.shape[0]) & (jj < self.top.shape[1])
                z = np.full(len(p), np.nan)
                z[ok] = self.top[ii[ok], jj[ok]]
                d = np.sqrt(h * h + (p[:, 2] - z) ** 2)
                best = np.fmin(best, np.where(np.isnan(d), np.inf, d))
        return best

    def elevation_on(self, geometry: GridGeometry) -> np.ndarray:
        """Highest reference z per column of ``geometry`` (rows = y), NaN where it has no point."""
        x, y = geometry.cell_centers()
        xs, ys = np.broadcast_arrays(x, y)
        out = np.full(xs.shape, -np.inf)
        k = int(round(geometry.resolution / self.cell))
        for dx in range(k):  # every reference cell inside the map column
            for dy in range(k):
                xy = np.stack([xs.ravel() - geometry.resolution / 2 + (dx + 0.5) * self.cell,
                               ys.ravel() - geometry.resolution / 2 + (dy + 0.5) * self.cell], 1)
                i, j, inside = self._cells(xy)
                z = np.full(len(xy), np.nan)
                z[inside] = self.top[i[inside], j[inside]]
                out = np.fmax(out, z.reshape(xs.shape))
        out[np.isinf(out)] = np.nan
        return out


def read_reference(path: str | Path, frame: LocalFrame, cell: float = 0.25) -> ReferenceSurface:
    """A LAS/LAZ cloud as a ``ReferenceSurface`` in ``frame``; ValueError names the file."""
    import laspy

    path = Path(path)
    try:
        las = laspy.read(path)
    except (OSError, laspy.errors.LaspyException) as exc:
        raise ValueError(f"{path}: cannot read the point cloud ({exc})") from None
    crs = las.header.parse_crs() or frame.utm_crs
    x, y, z = np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)
    lon, lat = Transformer.from_crs(crs, WGS84, always_xy=True).transform(x, y)
    mx, my, mz = frame.from_geodetic(lat, lon, z)
    return ReferenceSurface.from_points(np.stack([mx, my, mz], 1), cell)


@dataclass(frozen=True)
class CloudScore:
    scored: int  # points over the reference (the others are not scored)
    within_half: float  # share within 0.5 m of the surface
    within_1m: float


def score_points(surface: ReferenceSurface, points: np.ndarray) -> CloudScore:
    p = np.asarray(points, np.float64)
    p = p[surface.covers(p)]
    if not len(p):
        return CloudScore(0, float("nan"), float("nan"))
    d = surface.distance(p)
    return CloudScore(len(p), float((d <= 0.5).mean()), float((d <= 1.0).mean()))


@dataclass(frozen=True)
class ElevationScore:
    columns: int  # columns both the map and the reference cover
    median: float  # absolute difference, metres
    p90: float


def score_elevation(surface: ReferenceSurface, elevation: np.ndarray, geometry: GridGeometry) -> ElevationScore:
    """The map's elevation layer (top of the highest voxel) against the reference's highest point per column."""
    ref = surface.elevation_on(geometry)
    both = np.isfinite(ref) & np.isfinite(elevation)
    if not both.any():
        return ElevationScore(0, float("nan"), float("nan"))
    diff = np.abs(elevation[both] - ref[both])
    return ElevationScore(int(both.sum()), float(np.median(diff)), float(np.percentile(diff, 90)))
