"""Stereo geometry on exact synthetic views: a noise-textured plane at a known distance."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.depth import Frame, GroundTruthDepth, MatchConfig, StereoDepth, StereoMatcher, make_source, rectify
from layerpilot.depth.evaluate import score
from layerpilot.depth.synthetic import intrinsics, look_pose, noise_texture, plane_frame

SIZE = (640, 480)
ALT = 30.0


@pytest.fixture(scope="module")
def texture() -> np.ndarray:
    return noise_texture(2048, seed=3)


def _pair(texture, offset, pitch=90.0, yaw=90.0, size=SIZE):
    K = intrinsics(*size)
    centre = np.array([0.0, 0.0, ALT])
    ref = plane_frame(look_pose(centre, yaw, pitch), K, size, texture, 150.0, stamp=2.0)
    other = plane_frame(look_pose(centre + np.asarray(offset, float), yaw, pitch), K, size, texture, 150.0, stamp=1.0)
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
    np.testing.assert_array_equal(cloud.origin, ref.center)
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
    px = np.rint(cloud.pixels).astype(int)
    np.testing.assert_array_equal(cloud.colors, ref.image[px[:, 1], px[:, 0]])


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
    small = plane_frame(ref.pose, intrinsics(320, 240), (320, 240), texture, 150.0)
    with pytest.raises(ValueError, match="other"):
        rectify(ref, small)


def test_frame_validation_names_the_argument():
    K = intrinsics(64, 48)
    with pytest.raises(ValueError, match="image"):
        Frame(np.zeros((48, 64), np.uint8), np.eye(4), K, 0.0)
    with pytest.raises(ValueError, match="pose"):
        Frame(np.zeros((48, 64, 3), np.uint8), np.eye(3), K, 0.0)
    with pytest.raises(ValueError, match="depth"):
        Frame(np.zeros((48, 64, 3), np.uint8), np.eye(4), K, 0.0, depth=np.zeros((48, 64)))


def test_ground_truth_source_backprojects_exactly(texture):
    ref, _ = _pair(texture, (2.0, 0.0, 0.0), pitch=60.0)
    cloud = GroundTruthDepth(max_depth=100.0).push(ref)
    assert np.abs(cloud.points[:, 2]).max() < 1e-3
    s = score(cloud, ref)
    assert s.precision == 1.0 and s.coverage == 1.0
    assert GroundTruthDepth().push(Frame(ref.image, ref.pose, ref.K, 0.0)) is None


def test_make_source_by_name():
    assert isinstance(make_source("stereo"), StereoDepth)
    assert isinstance(make_source("ground_truth"), GroundTruthDepth)
    with pytest.raises(ValueError, match="kind"):
        make_source("lidar")
