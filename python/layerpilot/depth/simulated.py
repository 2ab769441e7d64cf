"""Depth frames from the simulator's renderer, and the fixed set of rendered pairs the bench and tests use."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from layerpilot.depth.frames import Frame
from layerpilot.depth.picking import altitude_scene_depth


def to_frame(rendered, stamp: float) -> Frame:
    """``layerpilot.sim.render.Frame`` (same OpenCV camera convention) -> depth ``Frame``."""
    pose = np.eye(4)
    pose[:3, :3] = rendered.pose.rotation
    pose[:3, 3] = rendered.pose.centre
    return Frame(rendered.color, pose, rendered.K, stamp, rendered.depth)


@dataclass(frozen=True)
class PairSpec:
    """A reference view and a partner displaced sideways (camera x) by ``ratio`` x scene depth."""

    x: float
    y: float
    altitude: float  # above the terrain under the camera
    pitch_deg: float
    yaw_deg: float
    ratio: float = 0.06
    side: float = 1.0  # +1: partner to the camera's right, -1: to its left


# Altitudes 30-60 m, pitch 45-90 deg, both sides, over forest away from the launch clearing.
BENCH_PAIRS = tuple(
    PairSpec(x, y, alt, pitch, yaw, side=side)
    for (x, y, alt, pitch, yaw, side) in [
        (60, 40, 30, 90, 0, 1), (-70, 50, 30, 60, 45, -1), (80, -60, 30, 45, 135, 1),
        (-50, -80, 45, 90, 200, -1), (100, 90, 45, 60, 270, 1), (-110, 20, 45, 45, 315, -1),
        (30, -110, 60, 90, 90, 1), (-90, -30, 60, 60, 160, -1), (120, -20, 60, 45, 20, 1),
    ])


def render_pair(renderer, spec: PairSpec, stamp: float = 0.0) -> tuple[Frame, Frame]:
    """(newest, partner) frames; the partner is the earlier one (stamp - 0.5 s)."""
    from layerpilot.sim import camera_pose

    ground = float(renderer.world.terrain_height(spec.x, spec.y))
    centre = np.array([spec.x, spec.y, ground + spec.altitude])
    pose = camera_pose(centre, np.radians(spec.yaw_deg), spec.pitch_deg)
    ref = to_frame(renderer.render(pose), stamp)
    depth = altitude_scene_depth(ref, ground, 100.0)
    offset = spec.side * spec.ratio * depth * pose.rotation[:, 0]
    other = to_frame(renderer.render(camera_pose(centre + offset, np.radians(spec.yaw_deg), spec.pitch_deg)),
                     stamp - 0.5)
    return ref, other


def sideways_flight(renderer, start: tuple[float, float], heading_deg: float, altitude: float, pitch_deg: float,
                    speed: float, frames: int, period: float) -> list[Frame]:
    """Straight level flight at ``altitude`` over the terrain at ``start``, the camera looking 90 deg
    left of the track, so the motion is along the camera's x axis (the epipoles stay outside the image)."""
    from layerpilot.sim import camera_pose

    track = np.array([np.cos(np.radians(heading_deg)), np.sin(np.radians(heading_deg))])
    z = float(renderer.world.terrain_height(*start)) + altitude
    out = []
    for i in range(frames):
        x, y = np.asarray(start, float) + track * speed * period * i
        centre = np.array([x, y, z])
        pose = camera_pose(centre, np.radians(heading_deg + 90.0), pitch_deg)
        out.append(to_frame(renderer.render(pose), i * period))
    return out


def terrain_scene_depth(world, max_depth: float = 100.0):
    """Scene-depth estimate for the picker: altitude over the terrain under the camera."""
    return lambda frame: altitude_scene_depth(frame, float(world.terrain_height(*frame.center[:2])), max_depth)
