"""Scripted flights over an area of interest: survey lines, orbits and rings, as a survey pilot plans them.

Each is a :class:`Route`: waypoints (N, 4) of ``x, y, z, yaw`` in the map frame (ENU metres;
yaw in radians counter-clockwise from east, the heading the vehicle, and so the camera, holds on
the way to that waypoint) and the speed to fly them at. The mission core's ``Pilot`` flies them
through the same MAVLink path as the decision maker's waypoints, live and in lock-step.

The rules (docs/decide.md, "Scripted baselines") come from the camera's ground footprint
(``mission.footprint``): lines and rings are spaced by the view's extent across the track times
(1 - side overlap), placed so the views of the first and last line reach the area's edges, and
flown at the speed that puts consecutive frames (1 - front overlap) x the view's length along
the track apart, or one stereo baseline apart when no front overlap is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Sequence

import numpy as np

from layerpilot.camera import CameraConfig
from layerpilot.decide.behavior import Area, Pattern
from layerpilot.mission.footprint import footprint_width, survey_speed, view_band


@dataclass(frozen=True)
class Route:
    """Waypoints (N, 4) ``x, y, z, yaw`` and the speed (m/s) they are flown at."""

    waypoints: np.ndarray
    speed: float


def _unit(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])


def _left(u: np.ndarray) -> np.ndarray:
    return np.array([-u[1], u[0]])


class Region:
    """The area of interest as patterns plan over it: a disc, or a convex polygon kept counter-clockwise."""

    def __init__(self, centre: Sequence[float], radius: float = 0.0, polygon: np.ndarray | None = None) -> None:
        self.centre = np.asarray(centre, np.float64)
        self.radius = float(radius)
        self.polygon = polygon

    @classmethod
    def of(cls, area: Area, home: Sequence[float]) -> "Region":
        if area.shape == "circle":
            return cls.disc(area.center if area.center is not None else home, area.radius)
        return cls.convex(area.polygon)

    @classmethod
    def disc(cls, centre: Sequence[float], radius: float) -> "Region":
        c = np.asarray(centre, np.float64)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ValueError(f"centre must be (x, y), got {centre!r}")
        if not radius > 0:
            raise ValueError(f"radius must be > 0, got {radius}")
        return cls(c, radius)

    @classmethod
    def convex(cls, vertices: Sequence[Sequence[float]]) -> "Region":
        p = np.asarray(vertices, np.float64)
        if p.ndim != 2 or p.shape[0] < 3 or p.shape[1] != 2 or not np.all(np.isfinite(p)):
            raise ValueError(f"polygon must be 3 or more finite (x, y) vertices, got {vertices!r}")
        d = np.roll(p, -1, axis=0) - p
        turn = d[:, 0] * np.roll(d, -1, axis=0)[:, 1] - d[:, 1] * np.roll(d, -1, axis=0)[:, 0]
        if not (np.all(turn >= -1e-9) or np.all(turn <= 1e-9)) or abs(turn.sum()) < 1e-9:
            raise ValueError("polygon: a scripted pattern needs a convex area; split a concave one into convex parts")
        if turn.sum() < 0:
            p = p[::-1].copy()
        return cls(p.mean(axis=0), polygon=p)

    def span(self, u: np.ndarray) -> tuple[float, float]:
        """The region's extent along the unit vector ``u`` (projections onto it, from the origin)."""
        if self.polygon is None:
            c = float(self.centre @ u)
            return c - self.radius, c + self.radius
        s = self.polygon @ u
        return float(s.min()), float(s.max())

    def chord(self, origin: np.ndarray, u: np.ndarray) -> tuple[float, float] | None:
        """(s0, s1): the part of the line ``origin + s u`` inside the region, or None if it misses."""
        if self.polygon is None:
            d = origin - self.centre
            b, c = float(d @ u), float(d @ d) - self.radius**2
            disc = b * b - c
            if disc <= 0:
                return None
            return -b - math.sqrt(disc), -b + math.sqrt(disc)
        lo, hi = -math.inf, math.inf
        for v, w in zip(self.polygon, np.roll(self.polygon, -1, axis=0)):
            n = _left(w - v)  # inward for a counter-clockwise polygon: (origin + s u - v) . n >= 0
            a, rhs = float(u @ n), float((v - origin) @ n)
            if abs(a) < 1e-12:
                if rhs > 1e-9:
                    return None
            elif a > 0:
                lo = max(lo, rhs / a)
            else:
                hi = min(hi, rhs / a)
        return (lo, hi) if hi - lo > 1e-9 else None

    def inset(self, d: float) -> "Region | None":
        """The points at least ``d`` metres inside the edge, or None when nothing is left."""
        if d <= 0:
            return self
        if self.polygon is None:
            return Region(self.centre, self.radius - d) if self.radius - d > 1e-6 else None
        points = [tuple(p) for p in self.polygon]
        for v, w in zip(self.polygon, np.roll(self.polygon, -1, axis=0)):
            n = _left(w - v) / np.linalg.norm(w - v)
            points = _clip(points, n, float(v @ n) + d)
            if len(points) < 3:
                return None
        p = np.array(points)
        area = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
        return Region(p.mean(axis=0), polygon=p) if area > 1e-6 else None

    def ring(self, step: float, toward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A closed loop (M + 1, 2) around the edge counter-clockwise, points at most ``step`` apart, from
        and back to the edge point nearest ``toward``; and the inward yaw (ENU rad) at each point."""
        if self.polygon is None:
            n = max(3, math.ceil(2 * math.pi * self.radius / step))
            d = toward - self.centre
            phi0 = math.atan2(d[1], d[0]) if np.hypot(*d) > 1e-9 else 0.0
            phi = phi0 + 2 * math.pi * np.arange(n + 1) / n
            pts = self.centre + self.radius * np.column_stack([np.cos(phi), np.sin(phi)])
            return pts, np.arctan2(-np.sin(phi), -np.cos(phi))
        pts, yaws = [], []
        for v, w in zip(self.polygon, np.roll(self.polygon, -1, axis=0)):
            k = max(1, math.ceil(np.linalg.norm(w - v) / step))
            inward = _left(w - v)
            for t in np.arange(k) / k:
                pts.append(v + t * (w - v))
                yaws.append(math.atan2(inward[1], inward[0]))
        p, y = np.array(pts), np.array(yaws)
        k = int(np.argmin(np.hypot(*(p - toward).T)))
        order = np.r_[np.arange(k, len(p)), np.arange(k + 1)]
        return p[order], y[order]


def _clip(points: list[tuple[float, float]], n: np.ndarray, c: float) -> list[tuple[float, float]]:
    """Sutherland-Hodgman: the polygon's part where p . n >= c."""
    out: list[tuple[float, float]] = []
    for k, p in enumerate(points):
        q = points[k - 1]
        fp, fq = float(np.dot(p, n)) - c, float(np.dot(q, n)) - c
        if (fp >= 0) != (fq >= 0):
            t = fq / (fq - fp)
            out.append((q[0] + t * (p[0] - q[0]), q[1] + t * (p[1] - q[1])))
        if fp >= 0:
            out.append(p)
    return out


def line_heading(region: Region, heading_deg: float | None) -> float:
    """The survey's line direction (ENU rad): as given, else along the edge across which the area is narrowest
    (fewest lines); east for a disc."""
    if heading_deg is not None:
        return math.radians(heading_deg)
    if region.polygon is None:
        return 0.0
    edges = np.roll(region.polygon, -1, axis=0) - region.polygon
    angles = np.arctan2(edges[:, 1], edges[:, 0])
    widths = [np.subtract(*region.span(_left(_unit(a)))[::-1]) for a in angles]
    return float(angles[int(np.argmin(widths))])


def _line_offsets(region: Region, n: np.ndarray, band: tuple[float, float], side_overlap: float,
                  placement: str = "edges") -> np.ndarray:
    """Track offsets along ``n`` of the fewest lines whose views, ``band`` (near, far) across each track,
    span the region with at least ``side_overlap`` of a view shared by neighbours: the first view's near
    edge and the last one's far edge on the region's edges, the lines between evenly spaced.
    ``centred`` (the paper's lawnmower): ceil(extent / spacing) lines exactly the spacing apart, centred
    on the region, those outside it dropped."""
    lo, hi = region.span(n)
    near, far = band
    width = far - near
    if placement == "centred":
        spacing = width * (1.0 - side_overlap)
        count = max(1, math.ceil((hi - lo) / spacing))
        offsets = (lo + hi) / 2 + (np.arange(count) - (count - 1) / 2) * spacing
        return offsets[(offsets > lo) & (offsets < hi)]
    if hi - lo <= width:
        return np.array([min(max((lo + hi) / 2 - (near + far) / 2, lo), hi)])
    count = math.ceil((hi - lo - width) / (width * (1.0 - side_overlap)) - 1e-9) + 1
    return np.linspace(lo - near, hi - far, count)


def survey_lines(region: Region, altitude: float, heading: float, band: tuple[float, float], side_overlap: float,
                 sideways: bool, start: Sequence[float] | None = None, placement: str = "edges") -> np.ndarray:
    """Boustrophedon lines along ``heading`` covering the region, started at the corner nearest ``start``.

    ``band``: the view's extent across the track (near, far), towards the camera for ``sideways``
    (the camera looks 90 deg left of the first line's direction and holds that yaw on every line),
    else centred on the track with the camera along it.
    """
    if not 0.0 <= side_overlap < 1.0:
        raise ValueError(f"side_overlap must be in [0, 1), got {side_overlap}")
    if not math.isfinite(altitude):
        raise ValueError(f"altitude must be finite, got {altitude}")
    start2 = region.centre if start is None else np.asarray(start, np.float64)[:2]
    best = None
    for flip in (1.0, -1.0):  # which side the lines start from (and a side camera looks to)
        u0 = flip * _unit(heading)
        n = _left(u0)
        offsets = _line_offsets(region, n, band, side_overlap, placement)
        for first in (1.0, -1.0):  # which way the first line runs
            rows = []
            for k, off in enumerate(offsets):
                u = u0 * (first if k % 2 == 0 else -first)
                origin = off * n
                span = region.chord(origin, u)
                if span is None:
                    continue
                yaw = math.atan2(n[1], n[0]) if sideways else math.atan2(u[1], u[0])
                rows += [(*(origin + s * u), altitude, yaw) for s in span]
            wp = np.array(rows)
            d = float(np.hypot(*(wp[0, :2] - start2)))
            if best is None or d < best[0] - 1e-9:
                best = (d, wp)
    return best[1]


def rings(region: Region, altitude: float, band: tuple[float, float], side_overlap: float, step: float,
          start: Sequence[float] | None = None, count: int | None = None) -> np.ndarray:
    """Closed orbits inset from the edge, camera inward, until the innermost view reaches the middle.

    ``band``: the view's extent (near, far) inwards from the track. The first ring sits where the
    view's near edge meets the area's edge (on it, if the camera sees behind the track); each next
    ring (far - near)(1 - side_overlap) further in. ``count`` limits the rings (1: the orbit).
    Each ring starts at its point nearest where the last one ended (``start`` for the first).
    """
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step}")
    near, far = band
    spacing = (far - near) * (1.0 - side_overlap)
    d = max(0.0, -near) if count != 1 else 0.0
    at = region.centre if start is None else np.asarray(start, np.float64)[:2]
    rows: list[np.ndarray] = []
    while count is None or len(rows) < count:
        ring = region.inset(d)
        if ring is None:
            break
        pts, yaw = ring.ring(step, at)
        rows.append(np.column_stack([pts, np.full(len(pts), altitude), yaw]))
        at = pts[0]
        if region.inset(d + far) is None:
            break
        d += spacing
    if not rows:
        raise ValueError(f"the area is too small for a ring {d:.1f} m inside its edge")
    return np.vstack(rows)


def densify(waypoints: np.ndarray, spacing: float, start: Sequence[float] | None = None) -> np.ndarray:
    """The same route with legs longer than ``spacing`` split evenly; inserted points carry the leg's end yaw
    and z (terrain following then sets each piece's height)."""
    if not spacing > 0:
        raise ValueError(f"spacing must be > 0, got {spacing}")
    out, prev = [], None if start is None else np.asarray(start, np.float64)[:2]
    for wp in waypoints:
        if prev is not None:
            k = math.ceil(float(np.hypot(*(wp[:2] - prev))) / spacing - 1e-9)
            for t in np.arange(1, k) / max(k, 1):
                out.append((*(prev + t * (wp[:2] - prev)), wp[2], wp[3]))
        out.append(tuple(wp))
        prev = wp[:2]
    return np.array(out)


def route_for(pattern: Pattern, region: Region, altitude: float, camera: CameraConfig, frame_rate_hz: float,
              baseline_ratio: float, max_range: float, start: Sequence[float] | None = None) -> Route:
    """The waypoints and speed of a behavior's pattern, from its camera at ``altitude`` above the ground."""
    band = view_band(camera, altitude, max_range)
    width = footprint_width(camera, altitude)
    along_track = pattern.kind == "survey"  # the camera looks along the track; else across it
    if pattern.kind in ("survey", "survey-side"):
        across = (-width / 2, width / 2) if along_track else band
        wp = survey_lines(region, altitude, line_heading(region, pattern.heading_deg), across,
                          pattern.side_overlap, not along_track, start, pattern.placement)
    elif pattern.kind in ("orbit", "orbit-rings"):
        wp = rings(region, altitude, band, pattern.side_overlap, pattern.step, start,
                   count=1 if pattern.kind == "orbit" else None)
    else:
        raise ValueError(f"pattern.kind {pattern.kind!r}: not a scripted pattern")
    if pattern.speed is not None:
        speed = pattern.speed
    elif pattern.front_overlap is None:
        speed = survey_speed(camera, altitude, frame_rate_hz, baseline_ratio)
    else:
        length = band[1] - band[0] if along_track else width
        speed = (1.0 - pattern.front_overlap) * length * frame_rate_hz
    return Route(wp, speed)


def path_length(waypoints: np.ndarray, start=None) -> float:
    """Horizontal length of the polyline through the waypoints (from ``start`` if given)."""
    p = np.asarray(waypoints, dtype=np.float64)[:, :2]
    if start is not None:
        p = np.vstack([np.asarray(start, dtype=np.float64)[:2], p])
    return float(np.sum(np.hypot(*np.diff(p, axis=0).T)))
