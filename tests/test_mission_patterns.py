"""Lawnmower and orbit waypoint generators."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerpilot.mission.patterns import footprint_width, lawnmower, orbit, path_length, survey_speed
from layerpilot.camera import CameraConfig, camera_pose


def test_footprint_width_of_default_camera():
    # 90 deg HFOV, 60 deg down, 30 m above ground: slant 34.64 m, width 2 * 34.64 * tan 45
    assert footprint_width(CameraConfig(), 30.0) == pytest.approx(69.282, abs=1e-3)
    with pytest.raises(ValueError, match="pitch_deg"):
        footprint_width(CameraConfig(pitch_deg=0.0), 30.0)


def test_survey_speed_spaces_frames_by_the_stereo_baseline():
    # 50 m above ground, 60 deg down: slant 57.74 m; 6 % of it per frame at 1 Hz, twice that at 2 Hz
    assert survey_speed(CameraConfig(), 50.0, 1.0, 0.06) == pytest.approx(3.464, abs=1e-3)
    assert survey_speed(CameraConfig(), 50.0, 2.0, 0.06) == pytest.approx(6.928, abs=1e-3)
    assert survey_speed(CameraConfig(pitch_deg=90.0), 50.0, 1.0, 0.1) == pytest.approx(5.0)
    with pytest.raises(ValueError, match="frame_rate_hz"):
        survey_speed(CameraConfig(), 50.0, 0.0, 0.06)


def test_lawnmower_lines_spacing_turns_and_coverage():
    wp = lawnmower((10.0, -20.0), 100.0, 45.0, CameraConfig(), 30.0, side_overlap=0.3)
    spacing = 69.282 * 0.7  # 48.50 m -> 5 lines cover 200 m
    assert wp.shape == (10, 4)
    ys = wp[::2, 1]
    assert np.allclose(np.diff(ys), spacing, atol=1e-2)
    assert np.allclose(ys, -20.0 + (np.arange(5) - 2) * spacing, atol=1e-2)
    assert np.all(wp[:, 2] == 45.0)
    # each line ends on the circle (turns at the edge), directions alternate, yaw along travel
    assert np.allclose(np.hypot(wp[:, 0] - 10.0, wp[:, 1] + 20.0), 100.0)
    dx = wp[1::2, 0] - wp[::2, 0]
    assert np.all(np.sign(dx) == [1, -1, 1, -1, 1])
    assert np.allclose(wp[::2, 3], np.where(dx > 0, 0.0, math.pi))
    # every point of the disc is within half a footprint of some line
    rng = np.random.default_rng(1)
    r = 100 * np.sqrt(rng.uniform(size=2000))
    a = rng.uniform(0, 2 * np.pi, 2000)
    py = -20.0 + r * np.sin(a)
    assert np.max(np.min(np.abs(py[:, None] - ys[None, :]), axis=1)) <= 69.282 / 2
    # length: chords 2*sqrt(R^2 - y^2) plus the turns between lines
    chords = 2 * np.sqrt(100.0 ** 2 - ((np.arange(5) - 2) * spacing) ** 2)
    assert path_length(wp) > chords.sum() + 4 * spacing - 1e-6
    assert chords.sum() == pytest.approx(647.1, abs=0.1)  # 2 x 48.6 + 2 x 174.9 + 200


def test_lawnmower_heading_rotates_the_pattern():
    wp = lawnmower((0.0, 0.0), 50.0, 30.0, CameraConfig(), 30.0, side_overlap=0.5, heading=math.pi / 2)
    # 34.64 m spacing over 100 m: 3 lines along north, at x = -34.64, 0, 34.64
    assert np.allclose(wp[::2, 0], [34.641, 0.0, -34.641], atol=1e-3)
    assert np.allclose(wp[::2, 3], [math.pi / 2, -math.pi / 2, math.pi / 2])


def test_orbit_circles_the_edge_looking_at_the_centre():
    wp = orbit((5.0, 5.0), 80.0, 40.0, step=10.0, start=(5.0, -100.0))
    n = math.ceil(2 * math.pi * 80 / 10)  # 51 segments
    assert wp.shape == (n + 1, 4)
    assert np.allclose(wp[0, :2], [5.0, -75.0])  # edge point nearest the start (south)
    assert np.allclose(wp[0], wp[-1])
    assert np.allclose(np.hypot(wp[:, 0] - 5, wp[:, 1] - 5), 80.0)
    seg = np.hypot(*np.diff(wp[:, :2], axis=0).T)
    assert seg.max() <= 10.0
    assert path_length(wp) == pytest.approx(2 * math.pi * 80, rel=2e-3)
    # counter-clockwise, and the camera's optical axis points horizontally at the centre
    a, b = wp[:-1, :2] - 5, wp[1:, :2] - 5
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    assert np.all(cross > 0)
    for x, y, z, yaw in wp[:5]:
        axis = camera_pose((x, y, z), yaw, 60.0).rotation[:, 2]
        to_centre = np.array([5 - x, 5 - y]) / 80.0
        assert np.allclose(axis[:2] / np.hypot(*axis[:2]), to_centre, atol=1e-9)


def test_bad_area_is_rejected_naming_the_argument():
    with pytest.raises(ValueError, match="radius"):
        orbit((0, 0), 0.0, 30.0)
    with pytest.raises(ValueError, match="centre"):
        lawnmower((0, 0, 0), 10.0, 30.0, CameraConfig(), 30.0)
    with pytest.raises(ValueError, match="side_overlap"):
        lawnmower((0, 0), 10.0, 30.0, CameraConfig(), 30.0, side_overlap=1.0)
