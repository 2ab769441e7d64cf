"""The heading policy: the yaw each rule commands, and what it does to stereo pairing on rendered frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerpilot.decide.behavior import Area, Behavior, Flight
from layerpilot.depth import StereoDepth
from layerpilot.depth.config import preset_for
from layerpilot.depth.picking import FramePicker
from layerpilot.eval.fixtures import terrain_scene_depth
from layerpilot.mission.heading import HeadingPolicy
from layerpilot.camera import CameraConfig
from layerpilot.sim import Renderer, World, WorldConfig
from layerpilot.camera import camera_pose

SPEED = 5.2  # m/s at 1 Hz: the survey speed of this camera at 50 m (0.09 x the 57.7 m slant range)


def _policy(heading: str, yaw_deg: float = 0.0) -> HeadingPolicy:
    flight = Flight(heading=heading, yaw_deg=yaw_deg)
    return HeadingPolicy(Behavior(weights={"fringe": 1.0}, flight=flight, area=Area(center=(100.0, 0.0))), (0, 0))


def test_each_rule_commands_its_yaw() -> None:
    position, east, north = (0.0, 0.0, 50.0), (30.0, 0.0), (0.0, 30.0)
    assert _policy("target").yaw(position, east) == pytest.approx(0.0)
    assert _policy("target").yaw(position, north) == pytest.approx(math.pi / 2)
    assert _policy("fixed", 90.0).yaw(position, east) == _policy("fixed", 90.0).yaw(position, north) \
        == pytest.approx(math.pi / 2)
    assert _policy("center").yaw(position, north) == pytest.approx(math.atan2(-30.0, 100.0))
    # sideways to the hop, on the side of the area's centre (100, 0): flying north, it lies to the right (east)
    assert _policy("side").yaw(position, north) == pytest.approx(0.0)
    assert _policy("side").yaw((0.0, 30.0, 50.0), (0.0, 0.0)) == pytest.approx(0.0)  # flying south: still east
    assert _policy("side").yaw((0.0, 5.0, 50.0), (60.0, 5.0)) == pytest.approx(-math.pi / 2)  # flying east: south


@pytest.fixture(scope="module")
def renderer():
    world = World(WorldConfig(seed=1))
    with Renderer(world, CameraConfig(width=320, height=240, pitch_deg=60.0)) as r:
        yield r


def _fly(renderer, policy: HeadingPolicy, hops: list[tuple[float, float]], frames_per_hop: int) -> list:
    """Frames at 1 Hz and the survey speed along straight hops, each with the yaw the policy commands."""
    z = float(renderer.world.terrain_height(0.0, 0.0)) + 50.0
    position, frames, t = np.array([-30.0, -30.0]), [], 0.0
    for dx, dy in hops:
        step = np.array([dx, dy]) / math.hypot(dx, dy) * SPEED
        yaw = policy.yaw(tuple(position), tuple(position + step * frames_per_hop))
        for _ in range(frames_per_hop):
            position = position + step
            frames.append(renderer.render(camera_pose(np.array([*position, z]), yaw, 60.0), t))
            t += 1.0
    return frames


def test_a_steady_heading_keeps_consecutive_frames_paired_where_facing_the_target_does_not(renderer) -> None:
    """Short hops with a quarter turn between them (east, north, east, ...), two frames each, as the old
    MCDM hops: facing each target turns the camera 90 deg per hop and the picker rejects the first frame of
    every hop for rotation; a fixed survey heading never turns, and every frame after the first pairs."""
    hops = [(1.0, 0.0), (0.0, 1.0)] * 4
    result = {}
    for rule in ("target", "fixed"):
        picker = FramePicker(preset_for(320).pick, scene_depth=terrain_scene_depth(renderer.world))
        for frame in _fly(renderer, _policy(rule, 90.0), hops, 2):
            picker.push(frame)
        result[rule] = (picker.pairs, picker.skipped["rotation"])
    assert result["fixed"] == (15, 0)  # 16 frames: only the first has no partner
    assert result["target"][1] >= 7 and result["target"][0] <= 8  # every hop but the first starts turned


def test_looking_sideways_maps_more_of_a_diagonal_hop_than_a_fixed_heading(renderer) -> None:
    """A hop 45 deg off a fixed north heading: the frames pair, but rectification turns the views far
    and keeps a smaller common area (it found no points at all before the zoom cap of depth.rectify);
    looking sideways to the same hop, every pair gives a third more points (why the shipped MCDM
    presets use ``side``)."""
    points = {}
    for rule in ("fixed", "side"):
        source = StereoDepth(preset_for(320), scene_depth=terrain_scene_depth(renderer.world))
        clouds = [source.push(f) for f in _fly(renderer, _policy(rule, 90.0), [(1.0, 1.0)], 4)]
        assert source.stats()["pairs"] == 3, rule
        points[rule] = [0 if c is None else len(c) for c in clouds[1:]]
    assert min(points["fixed"]) > 20_000  # measured 40.7-41.4 k points
    assert min(points["side"]) > 1.3 * max(points["fixed"])  # measured 56.7-57.0 k
