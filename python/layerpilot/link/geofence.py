"""The geofence: where the flight link may send the vehicle, whoever asks.

A circle or a polygon in the map frame (ENU metres, the same shapes as a behavior's area
of interest), widened by ``margin`` metres, and a band of heights above home. The link
checks every position target against it before anything is sent to the autopilot
(:class:`~layerpilot.link.link.FlightLink`); a mission builds its fence in one place,
``layerpilot.missionfile.geofence_for``. This module knows nothing of missions or
behaviors: the link sits below them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from layerpilot.config import ConfigError

KINDS = ("not finite", "outside the area", "altitude", "separation")  # what a refusal is about, for counting


class OutsideGeofence(ValueError):
    """A waypoint the fence does not allow; ``kind`` is one of :data:`KINDS`."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True)
class Geofence:
    """A circle (``center``, ``radius``) or polygon (``polygon`` vertices) plus ``margin``, and
    heights above home in [``alt_min``, ``alt_max``]. Build with :meth:`circle` or :meth:`polygon_of`."""

    shape: Literal["circle", "polygon"]
    center: tuple[float, float] = (0.0, 0.0)
    radius: float = 0.0
    polygon: tuple[tuple[float, float], ...] = ()
    margin: float = 0.0   # metres allowed beyond the circle or polygon
    alt_min: float = 2.0  # metres above home
    alt_max: float = 120.0

    def __post_init__(self) -> None:
        numbers = [self.margin, self.alt_min, self.alt_max, *self.center, self.radius]
        numbers += [c for vertex in self.polygon for c in vertex]
        if not all(math.isfinite(v) for v in numbers):
            raise ConfigError(f"geofence: every number must be finite ({self.describe()})")
        if self.margin < 0:
            raise ConfigError(f"geofence: margin must be >= 0 m, got {self.margin}")
        if not self.alt_min < self.alt_max:
            raise ConfigError(f"geofence: alt_min must be below alt_max ({self.alt_min} >= {self.alt_max})")
        if self.shape == "circle":
            if not self.radius > 0:
                raise ConfigError(f"geofence: a circle needs a radius > 0 m, got {self.radius}")
        elif self.shape == "polygon":
            if len(self.polygon) < 3 or _area(self.polygon) <= 0.0:
                raise ConfigError(f"geofence: a polygon needs at least 3 vertices enclosing an area, "
                                  f"got {list(self.polygon)}")
        else:
            raise ConfigError(f"geofence: shape must be 'circle' or 'polygon', got {self.shape!r}")

    @classmethod
    def circle(cls, center: tuple[float, float], radius: float, *, margin: float = 0.0,
               alt_min: float = 2.0, alt_max: float = 120.0) -> Geofence:
        return cls("circle", center=(float(center[0]), float(center[1])), radius=float(radius),
                   margin=float(margin), alt_min=float(alt_min), alt_max=float(alt_max))

    @classmethod
    def polygon_of(cls, vertices, *, margin: float = 0.0, alt_min: float = 2.0,
                   alt_max: float = 120.0) -> Geofence:
        return cls("polygon", polygon=tuple((float(x), float(y)) for x, y in vertices), margin=float(margin),
                   alt_min=float(alt_min), alt_max=float(alt_max))

    def describe(self) -> str:
        """``circle of radius 100 m around (0, 0) + 20 m margin, 2-120 m above home``."""
        if self.shape == "circle":
            where = f"circle of radius {self.radius:g} m around ({self.center[0]:g}, {self.center[1]:g})"
        else:
            shown = ", ".join(f"({x:g}, {y:g})" for x, y in self.polygon[:4])
            where = f"polygon of {len(self.polygon)} vertices {shown}" + (", ..." if len(self.polygon) > 4 else "")
        return f"{where} + {self.margin:g} m margin, {self.alt_min:g}-{self.alt_max:g} m above home"

    def distance_outside(self, x: float, y: float) -> float:
        """Horizontal metres beyond the circle or polygon (0 inside it; the margin not counted)."""
        if self.shape == "circle":
            return max(0.0, math.hypot(x - self.center[0], y - self.center[1]) - self.radius)
        if _inside(self.polygon, x, y):
            return 0.0
        n = len(self.polygon)
        return min(_segment_distance(x, y, self.polygon[i], self.polygon[(i + 1) % n]) for i in range(n))

    def check_area(self, x: float, y: float, z: float) -> None:
        """Raise :class:`OutsideGeofence` unless (x, y, z) is finite and (x, y) within the shape + margin."""
        check_finite(x, y, z)
        beyond = self.distance_outside(x, y) - self.margin
        if beyond > 0.0:
            raise OutsideGeofence("outside the area", f"{_point(x, y, z)} is {beyond:.1f} m outside the geofence "
                                                      f"({self.describe()}); not sent")

    def check(self, x: float, y: float, z: float, home_z: float) -> None:
        """Raise :class:`OutsideGeofence` naming the waypoint and the fence unless map-frame (x, y, z) is
        inside: finite, within the shape + margin, and ``alt_min <= z - home_z <= alt_max``."""
        self.check_area(x, y, z)
        check_altitude(x, y, z, home_z, self.alt_min, self.alt_max, "the geofence's limits")


def _point(x: float, y: float, z: float) -> str:
    return f"waypoint ({x:.1f}, {y:.1f}, {z:.1f})"


def check_finite(x: float, y: float, z: float) -> None:
    if not all(math.isfinite(v) for v in (x, y, z)):
        raise OutsideGeofence("not finite", f"{_point(x, y, z)} is not finite; not sent")


def check_altitude(x: float, y: float, z: float, home_z: float, alt_min: float, alt_max: float,
                   limits: str = "the limits") -> None:
    """Raise :class:`OutsideGeofence` unless ``alt_min <= z - home_z <= alt_max`` (metres above home)."""
    height = z - home_z
    if not alt_min <= height <= alt_max:
        raise OutsideGeofence("altitude", f"{_point(x, y, z)}: altitude {height:.1f} m above home is outside "
                                          f"{limits} [{alt_min:g}, {alt_max:g}] m; not sent")


def _area(polygon) -> float:
    n = len(polygon)
    return abs(sum(polygon[i][0] * polygon[(i + 1) % n][1] - polygon[(i + 1) % n][0] * polygon[i][1]
                   for i in range(n))) / 2.0


def _inside(polygon, x: float, y: float) -> bool:
    """Even-odd rule (ray casting toward +x)."""
    inside = False
    n = len(polygon)
    for i in range(n):
        (x1, y1), (x2, y2) = polygon[i], polygon[(i + 1) % n]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def _segment_distance(x: float, y: float, a: tuple[float, float], b: tuple[float, float]) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0 else max(0.0, min(1.0, ((x - a[0]) * dx + (y - a[1]) * dy) / length2))
    return math.hypot(x - a[0] - t * dx, y - a[1] - t * dy)
