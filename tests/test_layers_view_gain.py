"""The view_gain layer with real numbers: footprint geometry, a known unobserved patch, occlusion, staleness."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerpilot.grid import GridGeometry
from layerpilot.layers import LayerContext, compute_layers
from layerpilot.layers.view_gain import CameraView, footprint, view_gain
from layerpilot.map.columns import ColumnLayers
from layerpilot.camera import CameraConfig, camera_pose, pixel_rays

CAMERA = CameraConfig(width=320, height=240, hfov_deg=90.0, pitch_deg=60.0)
VFOV = math.degrees(2 * math.atan(math.tan(math.radians(45.0)) * 240 / 320))
NORTH = math.pi / 2
N = 240  # cells of 1 m; the grid is centred on the origin
NOW = 600.0


def _fresh_map() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Everything observed just now on flat ground at 0 m, all inside the area of interest."""
    observed = np.ones((N, N), bool)
    return observed, np.full((N, N), NOW, np.float32), np.zeros((N, N), np.float32), np.ones((N, N), bool)


def _cells(x0: float, x1: float, y0: float, y1: float) -> tuple[slice, slice]:
    """Rows and columns of the cells with centres in [x0, x1) x [y0, y1) (grid origin at -N/2)."""
    return slice(int(y0 + N / 2), int(y1 + N / 2)), slice(int(x0 + N / 2), int(x1 + N / 2))


def _at(gain: np.ndarray, x: float, y: float) -> float:
    return float(gain[int(y + N / 2), int(x + N / 2)])


def test_footprint_matches_the_ground_quadrilateral_of_the_real_camera() -> None:
    """Pitched 80 deg down (the top row 43 deg below the horizon) with a long range, the footprint is the
    quadrilateral where the renderer's corner rays meet the ground: its area by the shoelace formula."""
    view = CameraView(50.0, 80.0, 90.0, VFOV, 1000.0, heading="fixed", yaw=NORTH)
    mask, _ = footprint(view, NORTH, 1.0)
    pose = camera_pose((0.0, 0.0, 50.0), NORTH, 80.0)
    cam = CameraConfig(width=320, height=240, hfov_deg=90.0, pitch_deg=80.0)
    rays = pixel_rays(cam.intrinsics, pose, np.array([-0.5, 319.5, 319.5, -0.5]), np.array([-0.5, -0.5, 239.5, 239.5]))
    ground = pose.position[:2] + rays[:, :2] * (50.0 / -rays[:, 2:3])
    x, y = ground[:, 0], ground[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert 8000 < area < 8300
    assert float(mask.sum()) == pytest.approx(area, rel=0.02)
    rows, cols = np.nonzero(mask)
    assert (rows - mask.shape[0] // 2).max() == pytest.approx(y.max(), abs=1.0)  # it lies north of the drone


def test_a_footprint_over_a_known_unobserved_patch_scores_its_share() -> None:
    """All fresh but a 20 x 20 m hole 40-60 m north of the candidate: gain = 400 m^2 / footprint area."""
    observed, seen, top, aoi = _fresh_map()
    observed[_cells(-10, 10, 40, 60)] = False
    view = CameraView(50.0, 60.0, 90.0, VFOV, 100.0, heading="fixed", yaw=NORTH)
    area = float(footprint(view, NORTH, 1.0)[0].sum())
    assert 9000 < area < 10500  # ~87 m deep, ~115 m wide at the centre row
    gain = view_gain(observed, seen, top, aoi, NOW, 1.0, view, NORTH)
    assert _at(gain, 0, 0) == pytest.approx(400.0 / area, rel=0.08)
    assert _at(gain, 0, 100) == pytest.approx(0.0, abs=1e-4)  # standing north of the hole: looking away
    assert _at(gain, 100, 0) == pytest.approx(0.0, abs=1e-4)  # the footprint passes east of it
    # the same hole half stale instead (seen 150 s ago, stale after 300 s) is worth half as much
    observed[:] = True
    seen[_cells(-10, 10, 40, 60)] = NOW - 150.0
    assert _at(view_gain(observed, seen, top, aoi, NOW, 1.0, view, NORTH), 0, 0) == \
        pytest.approx(0.5 * 400.0 / area, rel=0.08)
    aoi[:] = False  # and nothing outside the area of interest is worth anything
    assert float(view_gain(observed, seen, top, aoi, NOW, 1.0, view, NORTH).max()) == 0.0


def test_a_tall_column_hides_the_patch_behind_it_from_far_away() -> None:
    """A 40 m column just south of the hole hides it from a camera 50 m up to the south, far or near;
    a 3 m wall hides a strip behind it from far away only; the column north of the hole hides nothing from the south."""
    observed, seen, top, aoi = _fresh_map()
    observed[_cells(-10, 10, 60, 70)] = False
    top[~observed] = np.nan  # unknown tops: the hole's ground is taken as the lowest known top (0 m)
    view = CameraView(50.0, 60.0, 90.0, VFOV, 100.0, heading="fixed", yaw=NORTH)
    open_gain = view_gain(observed, seen, top, aoi, NOW, 1.0, view, NORTH)
    top[_cells(-12, 12, 56, 60)] = 40.0  # the column, 4 m deep, right in front of the hole
    hidden = view_gain(observed, seen, top, aoi, NOW, 1.0, view, NORTH)
    far, near = (0, -5), (0, 45)  # hole 65-75 m away (line of sight 10 m above the column's top) / 15-25 m
    assert _at(open_gain, *far) > 0.015
    assert _at(hidden, *far) < 0.2 * _at(open_gain, *far)
    assert _at(hidden, *near) < 0.2 * _at(open_gain, *near)  # the sight line passes 12 m up at the column
    top[_cells(-12, 12, 56, 60)] = 3.0  # a low wall hides only what lies right behind it
    low = view_gain(observed, seen, top, aoi, NOW, 1.0, view, NORTH)
    assert _at(low, *near) == pytest.approx(_at(open_gain, *near), rel=0.05)
    assert 0.3 * _at(open_gain, *far) < _at(low, *far) < 0.8 * _at(open_gain, *far)  # a 4.2 m shadow at 70 m
    top[_cells(-12, 12, 56, 60)] = 0.0
    top[_cells(-12, 12, 72, 76)] = 40.0  # behind the hole: hides nothing from the south
    assert _at(view_gain(observed, seen, top, aoi, NOW, 1.0, view, NORTH), *far) == \
        pytest.approx(_at(open_gain, *far), rel=0.05)


def test_the_registered_layer_uses_the_heading_rule_and_needs_a_view() -> None:
    """Through the registry: 'side' looks 90 deg to the hop towards the centre; without a view, a clear error."""
    g = GridGeometry.centered(0.0, 0.0, 1.0, N, N)
    cols = ColumnLayers.empty(g)
    cols.observed[:] = True
    cols.last_seen[:] = NOW
    cols.elevation[:] = 0.0
    cols.observed[_cells(60, 80, -10, 10)] = False  # a hole far east
    aoi = np.ones((N, N), bool)
    side = CameraView(50.0, 60.0, 90.0, VFOV, 100.0, heading="side", center=(100.0, 0.0))
    ctx = LayerContext(now=NOW, position=(0.0, -50.0, 50.0), view=side, aoi=aoi)
    gain = compute_layers(cols, ctx, ["view_gain"]).layers["view_gain"]
    # a hop due north to (0, 0): the centre (east) is on the right, so the camera looks east, at the hole
    assert _at(gain, 0, 0) > 0.02
    # the same candidate with the camera facing the hop (north) sees none of it
    target = LayerContext(now=NOW, position=(0.0, -50.0, 50.0), view=CameraView(50.0, 60.0, 90.0, VFOV, 100.0),
                          aoi=aoi)
    assert _at(compute_layers(cols, target, ["view_gain"]).layers["view_gain"], 0, 0) < 1e-3
    with pytest.raises(ValueError, match="view_gain: the layer context needs the camera view"):
        compute_layers(cols, LayerContext(now=NOW), ["view_gain"])


@pytest.mark.parametrize("heading", ["target", "side", "fixed", "center"])
@pytest.mark.parametrize("shape, resolution", [((240, 240), 1.0), ((201, 317), 1.0), ((97, 103), 2.0)])
def test_a_heading_computed_only_where_the_working_grid_reads_it_gives_the_same_layer(heading, shape, resolution):
    """The layer asks for the heading at the working grid's cells only; it must be bit for bit the layer
    from the heading of every cell (a grid that is no multiple of the working cell included)."""
    from layerpilot.layers.view_gain import heading_yaw

    rng = np.random.default_rng(3)
    observed = rng.random(shape) < 0.5
    seen = np.where(observed, rng.random(shape) * 500, np.nan)
    top = np.where(rng.random(shape) < 0.9, rng.random(shape) * 30, np.nan)
    aoi = rng.random(shape) < 0.8
    xs, ys = np.meshgrid((np.arange(shape[1]) + 0.5) * resolution - 60, (np.arange(shape[0]) + 0.5) * resolution - 60)
    view = CameraView(50.0, 60.0, 90.0, VFOV, 100.0, heading=heading, yaw=0.3, center=(3.0, 4.0))
    drone = (10.0, -5.0, 50.0)
    every_cell = heading_yaw(heading, drone, xs, ys, 0.3, (3.0, 4.0))
    where_read = view_gain(observed, seen, top, aoi, NOW, resolution, view,
                           lambda r, c: heading_yaw(heading, drone, xs[r, c], ys[r, c], 0.3, (3.0, 4.0)))
    assert where_read.tobytes() == view_gain(observed, seen, top, aoi, NOW, resolution, view, every_cell).tobytes()
    assert where_read.max() > 0.1
