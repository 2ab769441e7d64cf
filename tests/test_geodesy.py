"""The map frame on the Earth (layerpilot.geodesy): round trips, known distances, known UTM values."""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import CRS, Geod
from pyproj.database import query_utm_crs_info
from pyproj.aoi import AreaOfInterest

from layerpilot.geodesy import LocalFrame, utm_epsg

# The Brighton Beach photos' first camera position (46.8593 N, 91.9945 W, 198 m): UTM zone 15N.
BRIGHTON = LocalFrame(46.85927, -91.99449, 198.3)
GEOD = Geod(ellps="WGS84")


def test_round_trips_geodetic_and_utm_to_a_millimetre():
    rng = np.random.default_rng(3)
    x, y, z = (rng.uniform(-800, 800, 500), rng.uniform(-800, 800, 500), rng.uniform(-30, 120, 500))
    lat, lon, alt = BRIGHTON.to_geodetic(x, y, z)
    back = np.stack(BRIGHTON.from_geodetic(lat, lon, alt))
    assert np.abs(back - np.stack([x, y, z])).max() < 1e-3
    e, n, h = BRIGHTON.to_utm(x, y, z)
    assert np.abs(np.stack(BRIGHTON.from_utm(e, n, h)) - np.stack([x, y, z])).max() < 1e-3
    assert np.allclose(h, z + 198.3)
    # The origin is the origin in every direction.
    assert np.allclose(BRIGHTON.from_geodetic(46.85927, -91.99449, 198.3), 0.0, atol=1e-6)


@pytest.mark.parametrize("azimuth, east, north", [(90.0, 1, 0), (0.0, 0, 1), (225.0, -0.5**0.5, -0.5**0.5)])
def test_a_geodesic_from_the_origin_has_its_length_and_bearing_in_the_map(azimuth, east, north):
    lon, lat, _ = GEOD.fwd(BRIGHTON.lon, BRIGHTON.lat, azimuth, 600.0)
    x, y, z = BRIGHTON.from_geodetic(lat, lon, 210.0)
    assert x == pytest.approx(600.0 * east, abs=2e-3)
    assert y == pytest.approx(600.0 * north, abs=2e-3)
    assert z == pytest.approx(11.7)


def test_map_distances_are_ellipsoid_distances_within_1e7():
    rng = np.random.default_rng(5)
    x, y = rng.uniform(-1000, 1000, (2, 200))
    lat, lon, _ = BRIGHTON.to_geodetic(x, y, 0.0)
    _, _, dist = GEOD.inv(lon[:-1], lat[:-1], lon[1:], lat[1:])
    assert np.abs(np.hypot(np.diff(x), np.diff(y)) - dist).max() < 1e-7 * 2000


def test_utm_zone_is_the_origins_and_utm_values_are_the_known_ones():
    assert BRIGHTON.utm_crs.to_epsg() == 32615
    assert utm_epsg(47.397742, 8.545594) == 32632 and utm_epsg(-33.9, 18.4) == 32734
    for lat, lon in [(46.85927, -91.99449), (-33.9, 18.4), (0.5, 179.9)]:
        codes = {int(c.code) for c in query_utm_crs_info(datum_name="WGS 84",
                                                          area_of_interest=AreaOfInterest(lon, lat, lon, lat))}
        assert utm_epsg(lat, lon) in codes
    # On zone 15's central meridian (93 W) at the equator: easting 500 000 m, northing 0.
    equator = LocalFrame(0.0, -93.0, 0.0)
    e, n, _ = equator.to_utm(0.0, 0.0, 0.0)
    assert (float(e), float(n)) == (pytest.approx(500000.0, abs=1e-6), pytest.approx(0.0, abs=1e-6))
    # 1 km east of it, UTM's scale 0.9996 shortens the easting by 0.4 m.
    e, _, _ = equator.to_utm(1000.0, 0.0, 0.0)
    assert float(e) - 500000.0 == pytest.approx(999.6, abs=1e-3)


def test_the_export_crs_is_a_transverse_mercator_centred_on_the_origin():
    crs = BRIGHTON.crs
    assert crs.is_projected and crs.to_epsg() is None
    params = {p.name: p.value for p in crs.coordinate_operation.params}
    assert params["Latitude of natural origin"] == 46.85927
    assert params["Longitude of natural origin"] == -91.99449
    assert params["Scale factor at natural origin"] == 1.0
    assert [a.direction for a in crs.axis_info] == ["east", "north"]
    assert CRS.from_wkt(crs.to_wkt()) == crs


@pytest.mark.parametrize("bad, message", [((np.nan, 0.0, 0.0), "finite"), (([1, 2], [1, 2, 3], 0), "broadcast")])
def test_bad_coordinates_get_a_clear_error(bad, message):
    with pytest.raises(ValueError, match=message):
        BRIGHTON.to_geodetic(*bad)


def test_a_bad_origin_gets_a_clear_error():
    with pytest.raises(ValueError, match="lat 91"):
        LocalFrame(91.0, 0.0)
    with pytest.raises(ValueError, match="alt"):
        LocalFrame(10.0, 0.0, float("nan"))
