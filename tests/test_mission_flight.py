"""Stereo-aware flight from the mission's camera: footprint hops, survey speed, the view the pilot hands its layers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from layerpilot.decide.behavior import load_behavior, preset_names
from layerpilot.map import VoxelMap
from layerpilot.mission.build import build_pilot
from layerpilot.missionfile import Mission
from layerpilot.mission.flight import footprint_hops
from layerpilot.mission.footprint import vertical_fov_deg
from layerpilot.mission.pilot import PilotConfig
from layerpilot.camera import CameraConfig
from layerpilot.sim.simulator import SimConfig

CAMERA = CameraConfig(width=320, height=240, hfov_deg=90.0, pitch_deg=60.0)


def test_hop_radii_follow_the_camera_footprint() -> None:
    # slant range to the image centre 50 / sin 60 = 57.74 m; centre-row width 2 * 57.74 * tan 45 = 115.5 m;
    # ground reach sqrt(100^2 - 50^2) = 86.60 m
    r_e, r_i = footprint_hops(CAMERA, 50.0, 100.0)
    assert r_e == pytest.approx(115.47 / 4, abs=0.01) and r_i == pytest.approx(28.87 + 2 * 86.60, abs=0.02)
    wide = footprint_hops(dataclasses.replace(CAMERA, hfov_deg=120.0), 50.0, 100.0)
    high = footprint_hops(CAMERA, 80.0, 100.0)
    assert wide[0] == pytest.approx(r_e * math.tan(math.radians(60)), rel=1e-6)  # r_e grows with tan(hfov / 2)
    assert high[0] == pytest.approx(r_e * 80 / 50, rel=1e-6) and high[1] < r_i  # higher: wider, less reach
    assert vertical_fov_deg(CAMERA) == pytest.approx(73.74, abs=0.01)
    with pytest.raises(ValueError, match="max_range must exceed the height"):
        footprint_hops(CAMERA, 120.0, 100.0)


def test_a_preset_without_metres_hops_with_the_footprint_and_metres_in_a_file_win(tmp_path) -> None:
    sim = SimConfig(camera=CAMERA, frame_rate_hz=1.0)
    balanced = build_pilot(dataclasses.replace(Mission(), decide=PilotConfig(behavior="balanced"), sim=sim).core)
    assert balanced.behavior.r_e == pytest.approx(28.87, abs=0.01) and balanced.behavior.r_i == pytest.approx(202.07, abs=0.02)
    path = tmp_path / "metres.toml"
    path.write_text("r_e = 12.0\nr_i = 90.0\n[weights]\nfringe = 1.0\n")
    metres = build_pilot(dataclasses.replace(Mission(), decide=PilotConfig(behavior=str(path)), sim=sim).core)
    assert (metres.behavior.r_e, metres.behavior.r_i) == (12.0, 90.0)


def test_every_shipped_preset_loads_and_either_decides_or_flies_a_pattern() -> None:
    for name in preset_names():
        b = load_behavior(name)
        assert bool(b.weights) != b.deterministic, name  # survey-refly does both: a pattern, then plans


def _seen_square(half: float) -> object:
    m = VoxelMap(1.0)
    xs, ys = np.meshgrid(np.arange(-half, half) + 0.5, np.arange(-half, half) + 0.5)
    pts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1).astype(np.float32)
    m.insert(pts, np.array([0.0, 0.0, 30.0]), stamp=1.0)
    return m.column_layers(-128, -128, 256, 256)


def test_the_view_side_preset_flies_sideways_at_the_survey_speed_with_footprint_hops() -> None:
    """What build_pilot (both drivers' pilot) makes of the preset on the default mission's camera."""
    mission = dataclasses.replace(Mission(), decide=PilotConfig(behavior="view-side"),
                                  sim=SimConfig(camera=CAMERA, frame_rate_hz=1.0))
    pilot = build_pilot(mission.core)
    assert pilot.behavior.r_e == pytest.approx(28.87, abs=0.01) and pilot.behavior.r_i == pytest.approx(202.07, abs=0.02)
    assert pilot.cruise_speed == pytest.approx(0.09 * 50 / math.sin(math.radians(60)), rel=1e-6)  # 5.20 m/s
    assert pilot.view is not None and pilot.view.heading == "side" and pilot.view.height == 50.0
    command = pilot.step((0.0, 0.0, 50.0), 2.0, _seen_square(15))
    x, y, _ = command.position
    assert math.hypot(x, y) >= pilot.behavior.r_e - 1.0 and command.speed == pilot.cruise_speed
    track = math.atan2(y, x)
    off = math.remainder(command.yaw - track, 2 * math.pi)
    assert abs(abs(off) - math.pi / 2) < 1e-6  # the camera looks square to the hop...
    assert math.cos(command.yaw) * -x + math.sin(command.yaw) * -y > 0  # ...towards the area's centre (home)
    assert command.decision.contributions["view_gain"] > 0.5  # most of that view is still unseen
