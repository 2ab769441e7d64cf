"""The map frame on the Earth: a local east/north/up frame anchored at an origin.

layerpilot's map frame is metric, x east, y north, z up. For real photos and for
GIS exports it needs a place on the Earth; :class:`LocalFrame` gives it one.

Definition (and why): x, y are a transverse Mercator projection of WGS 84 centred
on the origin (scale 1 there, no false easting/northing), z is the height above
the origin's height. Inside a survey area this is the ENU tangent frame to well
under a millimetre horizontally (the scale error of this projection is d^2/2R^2:
1.2e-8 at 1 km), and it has two advantages over a true tangent plane:

- The frame *is* a projected CRS (:attr:`LocalFrame.crs`), so layers export to GIS
  in their own grid, exactly, without resampling; QGIS reprojects on the fly.
- Level ground stays level: a tangent plane's z falls away by d^2/2R (2 cm at
  500 m, 8 cm at 1 km), which would tilt an elevation layer.

Heights are passed through: z = alt - origin.alt in whatever vertical reference
the inputs use (EXIF GPS altitude is usually above mean sea level); no geoid
model is applied. All projection arithmetic is pyproj's (PROJ); the functions are
vectorised over NumPy arrays and broadcast their inputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from pyproj import CRS, Transformer
from pyproj.crs import ProjectedCRS
from pyproj.crs.coordinate_operation import TransverseMercatorConversion

WGS84 = CRS.from_epsg(4326)


def _finite(name: str, *arrays) -> tuple[np.ndarray, ...]:
    """Float arrays broadcast to one shape; a clear error for NaN/inf or bad shapes."""
    try:
        out = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in arrays))
    except ValueError as exc:
        raise ValueError(f"{name}: coordinate arrays do not broadcast: {exc}") from None
    for a in out:
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: coordinates must be finite (got NaN or inf)")
    return tuple(np.array(a) for a in out)


def utm_epsg(lat: float, lon: float) -> int:
    """EPSG code of the standard WGS 84 UTM zone holding (lat, lon): 326zz north, 327zz south."""
    zone = int((lon + 180.0) // 6.0) % 60 + 1
    return (32600 if lat >= 0.0 else 32700) + zone


@dataclass(frozen=True)
class LocalFrame:
    """The map frame anchored at ``lat``, ``lon`` (degrees, WGS 84) and ``alt`` (metres)."""

    lat: float
    lon: float
    alt: float = 0.0

    def __post_init__(self) -> None:
        for name in ("lat", "lon", "alt"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"origin {name} must be finite, got {getattr(self, name)}")
        if not -80.0 <= self.lat <= 84.0:
            raise ValueError(f"origin lat {self.lat} is outside [-80, 84] (UTM's latitude range)")
        if not -180.0 <= self.lon <= 180.0:
            raise ValueError(f"origin lon {self.lon} is outside [-180, 180]")

    @cached_property
    def crs(self) -> CRS:
        """The map frame's horizontal axes as a projected CRS (for GeoTIFF and other exports)."""
        conversion = TransverseMercatorConversion(
            latitude_natural_origin=self.lat,
            longitude_natural_origin=self.lon,
            false_easting=0.0,
            false_northing=0.0,
            scale_factor_natural_origin=1.0,
        )
        return ProjectedCRS(
            conversion=conversion,
            geodetic_crs=WGS84,
            name=f"layerpilot map frame at {self.lat:.7f}, {self.lon:.7f}",
        )

    @cached_property
    def utm_crs(self) -> CRS:
        """The WGS 84 UTM zone of the origin."""
        return CRS.from_epsg(utm_epsg(self.lat, self.lon))

    @cached_property
    def _from_geodetic(self) -> Transformer:
        return Transformer.from_crs(WGS84, self.crs, always_xy=True)

    @cached_property
    def _to_utm(self) -> Transformer:
        return Transformer.from_crs(self.crs, self.utm_crs, always_xy=True)

    def from_geodetic(self, lat, lon, alt) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lat deg, lon deg, alt m) -> map frame (x east, y north, z up) in metres."""
        lat, lon, alt = _finite("from_geodetic", lat, lon, alt)
        x, y = self._from_geodetic.transform(lon, lat)
        return np.asarray(x), np.asarray(y), alt - self.alt

    def to_geodetic(self, x, y, z) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Map frame metres -> (lat deg, lon deg, alt m)."""
        x, y, z = _finite("to_geodetic", x, y, z)
        lon, lat = self._from_geodetic.transform(x, y, direction="INVERSE")
        return np.asarray(lat), np.asarray(lon), z + self.alt

    def to_utm(self, x, y, z) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Map frame metres -> (easting, northing, alt) in the origin's UTM zone."""
        x, y, z = _finite("to_utm", x, y, z)
        e, n = self._to_utm.transform(x, y)
        return np.asarray(e), np.asarray(n), z + self.alt

    def from_utm(self, easting, northing, alt) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(easting, northing, alt) in the origin's UTM zone -> map frame metres."""
        e, n, alt = _finite("from_utm", easting, northing, alt)
        x, y = self._to_utm.transform(e, n, direction="INVERSE")
        return np.asarray(x), np.asarray(y), alt - self.alt
