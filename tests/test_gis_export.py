"""`layerpilot layers export`: GeoTIFFs that Debian's GDAL reads with the right CRS, extent and values."""

from __future__ import annotations

import json
import subprocess
import time

import numpy as np
import pytest

from layerpilot.bus.session import free_endpoint
from layerpilot.cli import main
from layerpilot.eval.geotiff import MAP_LAYERS, exportable_layers
from layerpilot.eval.run_frame import write_run_frame
from layerpilot.geodesy import LocalFrame
from layerpilot.map import VoxelMap
from layerpilot.missionfile import load_mission
from layerpilot.sim.endpoint_config import SITL_DATUM
from layerpilot.sim.world import World
from conftest import SMALL_MISSION_NODES, free_tcp_port, start_up, stop_up

FRAME = LocalFrame(46.85927, -91.99449, 198.3)  # the Brighton Beach photos' first camera


def gdalinfo(path) -> dict:
    return json.loads(subprocess.run(["gdalinfo", "-json", "-stats", str(path)], check=True,
                                     capture_output=True, text=True).stdout)


def gdal_value(path, x: float, y: float) -> list[float]:
    """Band values at map-frame (x, y), read by GDAL (gdallocationinfo -geoloc)."""
    out = subprocess.run(["gdallocationinfo", "-valonly", "-geoloc", str(path), str(x), str(y)], check=True,
                         capture_output=True, text=True).stdout
    return [float(v) for v in out.split()]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A run directory whose map is a slope (z = 0.2 + 0.1 x) on x in [-30, 0), y in [-20, 20), and its export."""
    run = tmp_path_factory.mktemp("run")
    m = VoxelMap(1.0)
    xs, ys = np.meshgrid(np.arange(-30, 0, 0.5) + 0.25, np.arange(-20, 20, 0.5) + 0.25)
    pts = np.stack([xs.ravel(), ys.ravel(), 0.2 + 0.1 * xs.ravel()], 1).astype(np.float32)
    colors = np.tile(np.array([[200, 100, 50]], np.uint8), (len(pts), 1))
    colors[pts[:, 1] > 10] = (20, 220, 40)
    m.insert(pts, np.array([-15.0, 0.0, 40.0]), colors, stamp=5.0)
    m.save(run / "map.ot")
    write_run_frame(run, FRAME)
    assert main(["layers", "export", str(run)]) == 0
    return run / "geotiff", m


def test_gdal_reads_the_map_frames_crs_and_extent(exported):
    out, _ = exported
    info = gdalinfo(out / "elevation_m.tif")
    wkt = info["coordinateSystem"]["wkt"]
    assert 'METHOD["Transverse Mercator"' in wkt and 'DATUM["World Geodetic System 1984"' in wkt
    assert 'PARAMETER["Latitude of natural origin",46.85927' in wkt
    assert 'PARAMETER["Longitude of natural origin",-91.99449' in wkt
    assert 'PARAMETER["Scale factor at natural origin",1' in wkt
    assert info["size"] == [30, 40]
    corners = info["cornerCoordinates"]
    assert corners["upperLeft"] == pytest.approx([-30.0, 20.0]) and corners["lowerRight"] == pytest.approx([0.0, -20.0])
    # GDAL's own WGS 84 extent equals what the origin and pyproj say the corners are.
    ring = np.array(info["wgs84Extent"]["coordinates"][0][:4])
    lat, lon, _ = FRAME.to_geodetic(np.array([-30.0, -30.0, 0.0, 0.0]), np.array([20.0, -20.0, -20.0, 20.0]), 0.0)
    assert np.abs(ring - np.stack([lon, lat], 1)).max() < 2e-7  # gdalinfo prints 7 decimals
    assert ring[:, 0].max() == pytest.approx(FRAME.lon, abs=1e-7)  # the map's east edge is x = 0: the origin


def test_band_values_are_the_maps(exported):
    out, m = exported
    elevation = gdalinfo(out / "elevation_m.tif")["bands"][0]
    assert elevation["type"] == "Float32" and elevation["noDataValue"] == "NaN"
    # column tops are voxel top faces: the slope z = 0.2 + 0.1 x rounded up to whole voxels
    columns = m.column_layers(-29.5, -19.5, 30, 40)
    assert elevation["minimum"] == pytest.approx(float(np.nanmin(columns.elevation)) + 198.3, abs=1e-3)
    assert elevation["maximum"] == pytest.approx(float(np.nanmax(columns.elevation)) + 198.3, abs=1e-3)
    for x, y in [(-29.5, -19.5), (-0.5, 19.5), (-12.5, 3.5)]:
        row, col = columns.geometry.cell_of(x, y)
        assert gdal_value(out / "elevation_m.tif", x, y) == pytest.approx([columns.elevation[row, col] + 198.3],
                                                                           abs=1e-3)
    color = gdalinfo(out / "color.tif")
    assert [b["colorInterpretation"] for b in color["bands"]] == ["Red", "Green", "Blue", "Alpha"]
    assert gdal_value(out / "color.tif", -5.5, 15.5) == [20, 220, 40, 255]  # north of y = 10: green, north up
    assert gdal_value(out / "color.tif", -5.5, -15.5) == [200, 100, 50, 255]
    distance = gdalinfo(out / "layer_distance.tif")["bands"][0]  # closest view / 100 m: 40 m below the camera
    assert distance["minimum"] == pytest.approx(float(columns.min_distance.min()) / 100, abs=6e-4)  # gdalinfo prints 3 decimals
    assert distance["maximum"] == pytest.approx(float(columns.min_distance.max()) / 100, abs=6e-4)  # gdalinfo prints 3 decimals
    assert 0.39 < distance["minimum"] < distance["maximum"] < 0.5  # corners: 47-50 m away


def test_a_map_without_a_place_gets_a_clear_error(tmp_path, capsys):
    m = VoxelMap(1.0)
    m.insert(np.array([[1.0, 2.0, 0.0]], np.float32), np.array([0.0, 0.0, 10.0]))
    m.save(tmp_path / "map.ot")
    assert main(["layers", "export", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "frame.json" in err and "--origin LAT LON ALT" in err


def test_export_names_only_layers_a_map_alone_gives(exported, tmp_path, capsys):
    """view_gain is registered (it needs a camera view and an area of interest): refused up front, with the
    list of what export can compute (the registry's layer_names for a map-only context)."""
    run = tmp_path / "run"
    run.mkdir()
    exported[1].save(run / "map.ot")
    write_run_frame(run, FRAME)
    assert main(["layers", "export", str(run), "--layer", "view_gain", "--layer", "nope"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("layerpilot: error: layer: cannot export 'view_gain' (needs a decision context, not a map alone), "
                   "'nope' (unknown); exportable: " + ", ".join(exportable_layers()))
    assert "view_gain" not in exportable_layers() and set(MAP_LAYERS) <= set(exportable_layers())
    assert not (run / "geotiff").exists()


def test_a_live_up_run_directory_is_exported_as_it_is(tmp_path, capsys):
    """`up` with a map snapshot: its simulator node writes frame.json beside the snapshots (the EKF origin,
    home on the ground), so `layers export` takes the run directory without --origin."""
    run = tmp_path / "run"
    mission = tmp_path / "mission.toml"
    mission.write_text(f"""
vehicles = ["uav1"]
speed = 4.0
mavlink_port = {free_tcp_port()}
[map_server]
snapshot = "{run / 'map.ot'}"
snapshot_period = 1.0
[sim.world]
size = 200.0
""" + SMALL_MISSION_NODES)
    up, lines = start_up(mission, free_endpoint(), tmp_path / "logs")
    try:
        end = time.monotonic() + 120  # a bound on waiting (take-off, then the first clouds), not a speed check
        while not ((run / "map.ot").is_file() and (run / "frame.json").is_file()):
            assert up.poll() is None and time.monotonic() < end, "".join(lines[-30:])
            time.sleep(0.5)
    finally:
        stop_up(up)
    ground = float(World(load_mission(mission).sim.world).terrain_height(0.0, 0.0))
    frame = json.loads((run / "frame.json").read_text())
    assert frame == pytest.approx({"lat": SITL_DATUM.lat, "lon": SITL_DATUM.lon, "alt": SITL_DATUM.alt + ground},
                                  abs=1e-6)
    assert main(["layers", "export", str(run)]) == 0
    assert "CRS: layerpilot map frame at 47.3977420, 8.5455940" in capsys.readouterr().out
    assert (run / "geotiff" / "elevation_m.tif").stat().st_size > 0
