"""Stereo geometry on exact synthetic views: a noise-textured plane at a known distance."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.depth import GroundTruthDepth, MatchConfig, StereoDepth, StereoMatcher, make_source, rectify
from layerpilot.depth.backproject import camera_points_to_cloud
from layerpilot.depth.evaluate import score
from layerpilot.eval.fixtures import noise_texture, plane_frame
from layerpilot.geometry import CameraFrame, CameraIntrinsics
from layerpilot.camera import camera_pose

SIZE = (640, 480)
ALT = 30.0


@pytest.fixture(scope="module")
def texture() -> np.ndarray:
    return noise_texture(2048, seed=3)


def _pair(texture, offset, pitch=90.0, yaw=90.0, size=SIZE):
    k = CameraIntrinsics.from_fov(*size, 60.0)
    centre = np.array([0.0, 0.0, ALT])
    ref = plane_frame(camera_pose(centre, np.radians(yaw), pitch), k, texture, 150.0, stamp=2.0)
    other = plane_frame(camera_pose(centre + np.asarray(offset, float), np.radians(yaw), pitch), k, texture, 150.0,
                        stamp=1.0)
    return ref, other


@pytest.mark.parametrize("offset, vertical, mirrored", [
    ((2.0, 0.0, 0.0), False, False),   # partner to the camera's right: reference is the left image
    ((-2.0, 0.0, 0.0), False, True),   # partner to the left: mirrored
    ((0.0, -2.0, 0.0), True, False),   # motion along the image's vertical axis: transposed pair
    ((0.0, 2.0, 0.0), True, True),
])
def test_plane_comes_back_at_its_distance(texture, offset, vertical, mirrored):
    ref, other = _pair(texture, offset)
    cloud, disp = StereoMatcher(MatchConfig()).cloud(ref, other)
    assert (disp.pair.vertical, disp.pair.mirrored) == (vertical, mirrored)
    assert disp.pair.baseline == pytest.approx(2.0, rel=1e-9)
    # nadir view of z = 0 from 30 m: every point's height is 0 and its depth is 30 m
    depth = ALT - cloud.points[:, 2]
    assert abs(np.median(depth) - ALT) < 0.01 * ALT
    assert np.quantile(np.abs(depth - ALT), 0.95) < 0.01 * ALT
    s = score(cloud, ref)
    assert s.precision > 0.99 and s.coverage > 0.8 and s.median_rel_error < 0.01
    np.testing.assert_array_equal(cloud.origin, ref.pose.position)
    assert cloud.stamp == 2.0 and cloud.points.dtype == np.float32 and cloud.colors.dtype == np.uint8


def test_oblique_plane_depth_per_pixel(texture):
    ref, other = _pair(texture, (1.5, 0.0, 0.0), pitch=60.0)
    cloud, _ = StereoMatcher(MatchConfig()).cloud(ref, other)
    s = score(cloud, ref)
    assert s.median_rel_error < 0.01 and np.quantile(s.rel_errors, 0.95) < 0.02
    assert np.abs(cloud.points[:, 2]).max() < 0.05 * ALT / np.sin(np.radians(60))


def test_colors_come_from_the_reference_pixels(texture):
    ref, other = _pair(texture, (2.0, 0.0, 0.0))
    cloud, _ = StereoMatcher(MatchConfig()).cloud(ref, other)
    uv, _ = ref.project(cloud.points)
    px = np.rint(uv).astype(int)  # the pixels the points came from, up to rounding at half pixels
    assert np.mean(np.all(cloud.colors == ref.image[px[:, 1], px[:, 0]], axis=1)) > 0.99


def test_half_scale_matching_keeps_the_plane(texture):
    ref, other = _pair(texture, (2.0, 0.0, 0.0))
    cloud, _ = StereoMatcher(MatchConfig(scale=0.5, num_disparities=32)).cloud(ref, other)
    s = score(cloud, ref, scale=0.5)
    assert s.precision > 0.99 and s.coverage > 0.75 and s.median_rel_error < 0.02


def test_depth_limit_drops_far_points(texture):
    ref, other = _pair(texture, (2.0, 0.0, 0.0))
    cloud, disp = StereoMatcher(MatchConfig(max_depth=29.0)).cloud(ref, other)
    assert len(cloud) < 0.5 * disp.disparity.size
    assert disp.rejected["depth_range"] > 0.3 * disp.disparity.size
    assert np.all(ALT - cloud.points[:, 2] <= 29.0 * 1.0001)


def test_rectify_rejects_bad_pairs(texture):
    ref, _ = _pair(texture, (2.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="baseline"):
        rectify(ref, ref)
    small = plane_frame(ref.pose, CameraIntrinsics.from_fov(320, 240, 60.0), texture, 150.0)
    with pytest.raises(ValueError, match="other"):
        rectify(ref, small)


def test_ground_truth_source_backprojects_exactly(texture):
    ref, _ = _pair(texture, (2.0, 0.0, 0.0), pitch=60.0)
    cloud = GroundTruthDepth(max_depth=100.0).push(ref)
    assert np.abs(cloud.points[:, 2]).max() < 1e-3
    s = score(cloud, ref)
    assert s.precision == 1.0 and s.coverage == 1.0
    assert GroundTruthDepth().push(CameraFrame(ref.image, ref.pose, ref.intrinsics, 0.0)) is None


def test_ground_truth_source_equals_the_plain_backprojection_bit_for_bit(texture):
    """Every mission frame is back-projected for the evaluation's reference map: the fast path must
    give exactly the points and colors of rays(u, v) * z over the valid pixels."""
    ref, _ = _pair(texture, (2.0, 0.0, 0.0), pitch=60.0)
    depth = ref.depth.copy()
    depth[:40] = np.inf
    depth[40:50, :100], depth[60:70, :100] = np.nan, 0.0
    depth[70:80, :100] = 150.0  # beyond max_depth
    frame = CameraFrame(ref.image, ref.pose, ref.intrinsics, 2.0, depth)
    for stride in (1, 3):
        d = depth[::stride, ::stride]
        v, u = np.nonzero(np.isfinite(d) & (d > 0) & (d <= 100.0))
        z = d[v, u].astype(np.float64)
        u, v = u * stride, v * stride
        plain = camera_points_to_cloud(frame, frame.intrinsics.rays(u, v) * z[:, None], frame.image[v, u])
        cloud = GroundTruthDepth(max_depth=100.0, stride=stride).push(frame)
        assert len(cloud.points) == len(plain.points) > 1000
        np.testing.assert_array_equal(cloud.points, plain.points)
        np.testing.assert_array_equal(cloud.colors, plain.colors)


def test_make_source_by_name():
    assert isinstance(make_source("stereo"), StereoDepth)
    assert isinstance(make_source("ground_truth"), GroundTruthDepth)
    with pytest.raises(ValueError, match="kind"):
        make_source("lidar")


def test_forward_flight_while_turning_keeps_the_rectified_zoom_bounded(texture):
    """A tilted camera flying forward and turning: alpha=0 rectification zoomed this pair 46x
    (disparities far beyond the search range, no points); the zoom is capped at 1.5x."""
    k = CameraIntrinsics.from_fov(320, 240, 90.0)
    ref = plane_frame(camera_pose(np.array([0.0, 0.0, ALT]), np.radians(90.0), 60.0), k, texture, 150.0, stamp=2.0)
    other = plane_frame(camera_pose(np.array([-0.3, -3.5, ALT]), np.radians(94.0), 60.0), k, texture, 150.0,
                        stamp=1.0)
    cloud, disp = StereoMatcher(MatchConfig(num_disparities=48, block_size=3)).cloud(ref, other)
    assert disp.pair.f == pytest.approx(1.5 * k.fx)
    s = score(cloud, ref)
    assert s.precision > 0.9 and s.coverage > 0.1 and s.median_rel_error < 0.02, s
