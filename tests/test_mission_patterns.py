"""Scripted baselines: footprint geometry, survey lines, sideways lines, orbits and rings, checked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerpilot.camera import CameraConfig, camera_pose
from layerpilot.decide.behavior import Pattern
from layerpilot.mission.footprint import footprint_width, survey_speed, view_band
from layerpilot.mission.patterns import Region, densify, path_length, rings, route_for, survey_lines

NADIR = CameraConfig(320, 240, pitch_deg=90.0)  # 90 deg across, 73.74 deg along
OBLIQUE = CameraConfig(320, 240, pitch_deg=60.0)


def test_footprint_width_of_default_camera():
    # 90 deg HFOV, 60 deg down, 30 m above ground: slant 34.64 m, width 2 * 34.64 * tan 45
    assert footprint_width(CameraConfig(), 30.0) == pytest.approx(69.282, abs=1e-3)
    with pytest.raises(ValueError, match="pitch_deg"):
        footprint_width(CameraConfig(pitch_deg=0.0), 30.0)


def test_view_band_near_and_far_edges():
    # nadir from 50 m: tan(73.74/2) = 0.75, so 37.5 m either side
    assert view_band(NADIR, 50.0, 100.0) == pytest.approx((-37.5, 37.5), abs=1e-3)
    # 60 deg down: bottom row 96.87 deg (6.024 m behind), top row 23.13 deg (117.05 m) capped at the
    # ground reach of 100 m range from 50 m up: sqrt(100^2 - 50^2) = 86.60 m
    assert view_band(OBLIQUE, 50.0, 100.0) == pytest.approx((-6.024, 86.603), abs=1e-3)
    assert view_band(OBLIQUE, 50.0, 200.0)[1] == pytest.approx(117.05, abs=0.01)


def test_survey_speed_spaces_frames_by_the_stereo_baseline():
    # 50 m above ground, 60 deg down: slant 57.74 m; 6 % of it per frame at 1 Hz, twice that at 2 Hz
    assert survey_speed(CameraConfig(), 50.0, 1.0, 0.06) == pytest.approx(3.464, abs=1e-3)
    assert survey_speed(CameraConfig(), 50.0, 2.0, 0.06) == pytest.approx(6.928, abs=1e-3)
    assert survey_speed(CameraConfig(pitch_deg=90.0), 50.0, 1.0, 0.1) == pytest.approx(5.0)
    with pytest.raises(ValueError, match="frame_rate_hz"):
        survey_speed(CameraConfig(), 50.0, 0.0, 0.06)


def _disc_points(centre, radius, n=3000, seed=1):
    rng = np.random.default_rng(seed)
    r = radius * np.sqrt(rng.uniform(size=n))
    a = rng.uniform(0, 2 * np.pi, n)
    return np.column_stack([centre[0] + r * np.cos(a), centre[1] + r * np.sin(a)])


def test_nadir_survey_follows_the_overlap_rule_by_hand():
    """Disc of 100 m at (10, -20), nadir camera 50 m up: footprint 100 m across, 75 m along.

    Side overlap 0.3: lines at most 70 m apart; 3 lines, the outer views on the edges: tracks at
    y = -20 - 50, -20, -20 + 50. Speed: stereo baseline 0.09 x 50 m per frame at 1 Hz = 4.5 m/s;
    with front overlap 0.8 instead: 0.2 x 75 m per frame = 15 m/s.
    """
    region = Region.disc((10.0, -20.0), 100.0)
    route = route_for(Pattern(kind="survey", side_overlap=0.3), region, 50.0, NADIR, 1.0, 0.09, 100.0,
                      start=(10.0, -20.0))
    wp = route.waypoints
    assert route.speed == pytest.approx(4.5)
    assert route_for(Pattern(kind="survey", front_overlap=0.8), region, 50.0, NADIR, 1.0, 0.09, 100.0).speed \
        == pytest.approx(15.0)
    assert wp.shape == (6, 4) and np.all(wp[:, 2] == 50.0)
    assert np.allclose(sorted(set(np.round(wp[:, 1], 6))), [-70.0, -20.0, 30.0])
    assert np.allclose(np.hypot(wp[:, 0] - 10.0, wp[:, 1] + 20.0), 100.0)  # lines end on the circle
    dx = wp[1::2, 0] - wp[::2, 0]
    assert np.all(dx[:-1] * dx[1:] < 0)  # boustrophedon: directions alternate
    assert np.allclose(np.cos(wp[::2, 3]), np.sign(dx)) and np.allclose(np.sin(wp[::2, 3]), 0.0, atol=1e-12)
    pts = _disc_points((10.0, -20.0), 100.0)
    assert np.max(np.min(np.abs(pts[:, 1:2] - np.array([[-70.0, -20.0, 30.0]])), axis=1)) <= 50.0


def test_survey_starts_at_the_corner_nearest_the_start():
    region = Region.disc((0.0, 0.0), 100.0)
    for start in [(-90.0, -40.0), (80.0, 60.0)]:
        wp = route_for(Pattern(kind="survey"), region, 50.0, NADIR, 1.0, 0.09, 100.0, start=start).waypoints
        corners = [wp[0, :2], wp[1, :2], wp[-2, :2], wp[-1, :2]]
        assert np.hypot(*(wp[0, :2] - start)) == pytest.approx(min(np.hypot(*(c - start)) for c in corners))


def test_side_survey_holds_one_yaw_and_its_views_cover_the_disc():
    """60 deg camera 50 m up looking 90 deg left of the first line: each view spans -6.024 .. 86.603 m across.
    Over a 200 m disc with side overlap 0.3: 3 lines, the first at the edge + 6.024 m, the last 86.60 m
    short of the far edge."""
    region = Region.disc((0.0, 0.0), 100.0)
    wp = survey_lines(region, 50.0, 0.0, view_band(OBLIQUE, 50.0, 100.0), 0.3, sideways=True, start=(0.0, -100.0))
    assert np.allclose(wp[:, 3], wp[0, 3])  # one yaw on every line
    look = np.array([math.cos(wp[0, 3]), math.sin(wp[0, 3])])
    offsets = np.unique(np.round(wp[:, :2] @ look, 6))
    assert len(offsets) == 3
    assert offsets[0] == pytest.approx(-100.0 + 6.024, abs=1e-3) and offsets[-1] == pytest.approx(100 - 86.603, abs=1e-3)
    assert np.all(np.diff(offsets) <= 92.627 * 0.7 + 1e-6)  # at least the stated overlap
    d = _disc_points((0.0, 0.0), 100.0) @ look
    seen = (d[:, None] >= offsets[None] - 6.024 - 1e-6) & (d[:, None] <= offsets[None] + 86.603 + 1e-6)
    assert seen.any(axis=1).all()


def test_polygon_survey_runs_along_the_long_side_and_stays_inside():
    # a 300 x 120 m rectangle rotated 30 deg: lines run along its 300 m side
    a = math.radians(30.0)
    u, n = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    corners = [s * 150 * u + t * 60 * n for s, t in [(-1, -1), (1, -1), (1, 1), (-1, 1)]]
    region = Region.convex(corners)
    wp = route_for(Pattern(kind="survey"), region, 50.0, NADIR, 1.0, 0.09, 100.0).waypoints
    legs = np.diff(wp[:, :2], axis=0)[::2]  # the lines (every other leg is a turn)
    assert np.allclose(np.abs(legs @ u), 300.0, atol=1e-6)
    assert np.allclose(np.unique(np.round(wp[:, :2] @ n, 6)), [-10.0, 10.0])  # 120 m wide: 2 lines, views on the edges
    with pytest.raises(ValueError, match="convex"):
        Region.convex([(0, 0), (100, 0), (100, 100), (50, 20), (0, 100)])


def test_orbit_circles_the_edge_looking_at_the_centre():
    region = Region.disc((5.0, 5.0), 80.0)
    wp = rings(region, 40.0, view_band(OBLIQUE, 40.0, 100.0), 0.3, 10.0, start=(5.0, -100.0), count=1)
    n = math.ceil(2 * math.pi * 80 / 10)  # 51 segments
    assert wp.shape == (n + 1, 4)
    assert np.allclose(wp[0, :2], [5.0, -75.0])  # edge point nearest the start (south)
    assert np.allclose(wp[0], wp[-1])
    assert np.allclose(np.hypot(wp[:, 0] - 5, wp[:, 1] - 5), 80.0)
    assert path_length(wp) == pytest.approx(2 * math.pi * 80, rel=2e-3)
    a, b = wp[:-1, :2] - 5, wp[1:, :2] - 5
    assert np.all(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] > 0)  # counter-clockwise
    for x, y, z, yaw in wp[:5]:
        axis = camera_pose((x, y, z), yaw, 60.0).rotation[:, 2]
        assert np.allclose(axis[:2] / np.hypot(*axis[:2]), np.array([5 - x, 5 - y]) / 80.0, atol=1e-9)


def test_rings_step_inward_until_the_view_reaches_the_middle():
    """R = 100 m, view -6.024 .. 86.603 m inward: the first ring 6.024 m inside the edge, the next
    92.627 x 0.7 = 64.839 m further in (radius 29.137 m), whose view passes the centre: 2 rings."""
    wp = rings(Region.disc((0.0, 0.0), 100.0), 50.0, view_band(OBLIQUE, 50.0, 100.0), 0.3, 10.0)
    radii = np.unique(np.round(np.hypot(wp[:, 0], wp[:, 1]), 3))
    assert radii == pytest.approx([100 - 6.024 - 64.839, 100 - 6.024], abs=1e-3)
    # a square's rings are squares inset by the same distances, the camera square to each side
    square = Region.convex([(-100, -100), (100, -100), (100, 100), (-100, 100)])
    wp = rings(square, 50.0, view_band(OBLIQUE, 50.0, 100.0), 0.3, 10.0)
    inset = 100 - np.max(np.abs(wp[:, :2]), axis=1)
    assert np.allclose(np.unique(np.round(inset, 3)), [6.024, 70.863], atol=1e-3)
    assert set(np.round(np.degrees(wp[:, 3]) % 360, 6)) <= {0.0, 90.0, 180.0, 270.0}


def test_densify_splits_long_legs_only():
    wp = np.array([[0.0, 0.0, 50.0, 0.0], [100.0, 0.0, 50.0, 0.0], [100.0, 10.0, 50.0, 1.0]])
    out = densify(wp, 25.0)
    assert np.allclose(out[:, 0], [0, 25, 50, 75, 100, 100]) and np.allclose(out[-1], wp[-1])
    assert np.all(np.hypot(*np.diff(out[:, :2], axis=0).T) <= 25.0 + 1e-9)


def test_bad_area_is_rejected_naming_the_argument():
    with pytest.raises(ValueError, match="radius"):
        Region.disc((0, 0), 0.0)
    with pytest.raises(ValueError, match="centre"):
        Region.disc((0, 0, 0), 10.0)
    with pytest.raises(ValueError, match="side_overlap"):
        Pattern(kind="survey", side_overlap=1.0)


def test_the_papers_lawnmower_keeps_its_centred_lines():
    """`lawnmower`: ceil(200 / 48.50) = 5 lines exactly 48.50 m apart (footprint 69.28 m x 0.7), centred."""
    wp = survey_lines(Region.disc((10.0, -20.0), 100.0), 45.0, 0.0, (-69.282 / 2, 69.282 / 2), 0.3, sideways=False,
                      start=(-100.0, -120.0), placement="centred")
    assert wp.shape == (10, 4)
    assert np.allclose(wp[::2, 1], -20.0 + (np.arange(5) - 2) * 69.282 * 0.7, atol=1e-2)
    assert np.allclose(np.hypot(wp[:, 0] - 10.0, wp[:, 1] + 20.0), 100.0)
    chords = 2 * np.sqrt(100.0 ** 2 - ((np.arange(5) - 2) * 69.282 * 0.7) ** 2)
    assert path_length(wp) > chords.sum() + 4 * 48.5 - 1e-3 and chords.sum() == pytest.approx(647.1, abs=0.1)
