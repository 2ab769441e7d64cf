"""Geodetic home <-> local ENU metres for the simulated vehicle.

A local tangent plane around the home point (equirectangular on the WGS-84
equatorial radius): over the few hundred metres of a survey area the error is
millimetres, far below GPS noise, and the round trip is exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

EARTH_RADIUS_M = 6378137.0


@dataclass(frozen=True)
class GeoOrigin:
    """Home point: latitude/longitude in degrees, altitude in metres above mean sea level."""

    lat: float = 47.397742  # the PX4/ArduPilot SITL default field near Zurich
    lon: float = 8.545594
    alt: float = 488.0

    def __post_init__(self) -> None:
        if not -90.0 < self.lat < 90.0:
            raise ValueError(f"lat: {self.lat} is outside (-90, 90)")
        if not -180.0 <= self.lon <= 180.0:
            raise ValueError(f"lon: {self.lon} is outside [-180, 180]")

    def to_geodetic(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """ENU metres from home -> (lat deg, lon deg, alt m AMSL)."""
        lat = self.lat + math.degrees(y / EARTH_RADIUS_M)
        lon = self.lon + math.degrees(x / (EARTH_RADIUS_M * math.cos(math.radians(self.lat))))
        return lat, lon, self.alt + z

    def to_enu(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt m AMSL) -> ENU metres from home."""
        y = math.radians(lat - self.lat) * EARTH_RADIUS_M
        x = math.radians(lon - self.lon) * EARTH_RADIUS_M * math.cos(math.radians(self.lat))
        return x, y, alt - self.alt
