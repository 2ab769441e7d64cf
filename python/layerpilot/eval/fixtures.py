"""Synthetic scenes with known ground truth, for tests, benchmarks and pictures.

Nothing here flies: these are the fixed inputs that tests, ``layerpilot bench ...`` and
the preview pictures feed to the algorithm packages.

* ``survey_clouds``: ground-truth depth clouds of a straight survey leg over the
  simulator's forest (``sim.World``, rendered by ``sim.Renderer``);
* ``area_survey_clouds``: the same camera flying a lawnmower over a whole world (the map's
  memory on a square kilometre);
* ``BENCH_PAIRS`` / ``render_pair`` / ``sideways_flight``: rendered stereo pairs and
  flights of the forest for the depth bench, preview and tests;
* ``plane_frame`` / ``noise_texture``: exact views of a textured ground plane through
  plane-induced homographies, whose depth is known in closed form (stereo geometry tests).

Rendering needs an OpenGL context (Mesa's software renderer will do): see ``layerpilot.sim.render``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from layerpilot.depth.picking import altitude_scene_depth
from layerpilot.geometry import CameraFrame, CameraIntrinsics, PointCloud, Pose
from layerpilot.camera import MOUNT_PITCH_DEG, CameraConfig, camera_pose


# --- survey leg over the forest ---------------------------------------------------------------

def survey_clouds(count: int, seed: int = 0, width: int = 640, height: int = 480, pitch_deg: float = MOUNT_PITCH_DEG,
                  max_depth: float = math.inf) -> list[PointCloud]:
    """Ground-truth depth clouds of ``count`` frames along a survey leg over the default forest of ``seed``.

    The camera (90 deg horizontal field of view, pitched ``pitch_deg`` down) flies 40-60 m
    above the terrain from x = -100 m eastwards, 15 m between frames, yaw within 0.3 rad
    of east; frame k is stamped k seconds. Every pixel that sees the world within
    ``max_depth`` (z-depth, metres) gives one point; sky gives none.
    """
    from layerpilot.depth.source import GroundTruthDepth
    from layerpilot.sim.render import Renderer
    from layerpilot.sim.world import World, WorldConfig

    world = World(WorldConfig(seed=seed))
    source = GroundTruthDepth(max_depth=max_depth)
    rng = np.random.default_rng(seed)
    clouds = []
    with Renderer(world, CameraConfig(width=width, height=height, pitch_deg=pitch_deg)) as renderer:
        for k in range(count):
            x, y = -100.0 + 15.0 * k, float(rng.uniform(-20, 20))
            z = float(world.terrain_height(x, y)) + rng.uniform(40, 60)
            frame = renderer.render(camera_pose((x, y, z), float(rng.uniform(-0.3, 0.3)), pitch_deg), float(k))
            clouds.append(source.push(frame))  # never None: rendered frames carry depth
    return clouds


def area_survey_clouds(world_size: float, seed: int = 0, width: int = 320, height: int = 240,
                       altitude: float = 50.0, line_spacing: float = 100.0, frame_spacing: float = 50.0,
                       max_depth: float = 100.0):
    """Yields ``(frame count, cloud)`` for a lawnmower survey over the whole ``world_size`` world.

    Lines run east and west in turn, ``line_spacing`` apart, a frame every ``frame_spacing``
    metres at ``altitude`` above the terrain, the camera (90 deg horizontal field of view)
    pitched 60 deg down along the line; frame k is stamped k seconds. A generator, so a
    square kilometre (hundreds of frames) never sits in memory at once.
    """
    from layerpilot.depth.source import GroundTruthDepth
    from layerpilot.sim.render import Renderer
    from layerpilot.sim.world import World, WorldConfig

    world = World(WorldConfig(seed=seed, size=world_size))
    source = GroundTruthDepth(max_depth=max_depth)
    half = world_size / 2 - frame_spacing / 2
    xs = np.arange(-half, half + 1e-9, frame_spacing)
    lines = np.arange(-half, half + 1e-9, line_spacing)
    poses = [(x, y, 0.0 if i % 2 == 0 else math.pi) for i, y in enumerate(lines) for x in (xs if i % 2 == 0 else xs[::-1])]
    with Renderer(world, CameraConfig(width=width, height=height, pitch_deg=60.0)) as renderer:
        for k, (x, y, yaw) in enumerate(poses):
            z = float(world.terrain_height(x, y)) + altitude
            frame = renderer.render(camera_pose((x, y, z), yaw, 60.0), float(k))
            yield len(poses), source.push(frame)


# --- rendered stereo pairs and flights --------------------------------------------------------

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


def render_pair(renderer, spec: PairSpec, stamp: float = 0.0) -> tuple[CameraFrame, CameraFrame]:
    """(newest, partner) frames from a ``sim.Renderer``; the partner is the earlier one (stamp - 0.5 s)."""
    ground = float(renderer.world.terrain_height(spec.x, spec.y))
    centre = np.array([spec.x, spec.y, ground + spec.altitude])
    pose = camera_pose(centre, np.radians(spec.yaw_deg), spec.pitch_deg)
    ref = renderer.render(pose, stamp)
    depth = altitude_scene_depth(ref, ground, 100.0)
    offset = spec.side * spec.ratio * depth * pose.rotation[:, 0]
    other = renderer.render(camera_pose(centre + offset, np.radians(spec.yaw_deg), spec.pitch_deg), stamp - 0.5)
    return ref, other


def sideways_flight(renderer, start: tuple[float, float], heading_deg: float, altitude: float, pitch_deg: float,
                    speed: float, frames: int, period: float) -> list[CameraFrame]:
    """Straight level flight at ``altitude`` over the terrain at ``start``, the camera looking 90 deg
    left of the track, so the motion is along the camera's x axis (the epipoles stay outside the image)."""
    track = np.array([np.cos(np.radians(heading_deg)), np.sin(np.radians(heading_deg))])
    z = float(renderer.world.terrain_height(*start)) + altitude
    out = []
    for i in range(frames):
        x, y = np.asarray(start, float) + track * speed * period * i
        pose = camera_pose(np.array([x, y, z]), np.radians(heading_deg + 90.0), pitch_deg)
        out.append(renderer.render(pose, i * period))
    return out


def terrain_scene_depth(world, max_depth: float = 100.0):
    """Scene-depth estimate for the picker: altitude over the terrain under the camera."""
    return lambda frame: altitude_scene_depth(frame, float(world.terrain_height(*frame.pose.position[:2])), max_depth)


# --- exact views of a textured plane ----------------------------------------------------------

def noise_texture(size: int = 2048, seed: int = 0) -> np.ndarray:
    """RGB texture with detail at every scale down to ~2 texels (matchable at any distance)."""
    rng = np.random.default_rng(seed)
    tex = np.zeros((size, size), np.float32)
    for cells in (8, 32, 128, 512, size // 2):
        layer = rng.random((cells, cells), np.float32)
        tex += cv2.resize(layer, (size, size), interpolation=cv2.INTER_CUBIC)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    rgb = np.stack([tex, 0.6 * tex + 0.2, 1.0 - 0.5 * tex], axis=2)
    return (255 * rgb).astype(np.uint8)


def plane_frame(pose: Pose, intrinsics: CameraIntrinsics, texture: np.ndarray, extent: float,
                stamp: float = 0.0) -> CameraFrame:
    """View of the plane z = 0 whose square [-extent/2, extent/2]^2 carries ``texture``, with exact z-depth."""
    w, h = intrinsics.size
    K = intrinsics.K
    R, C = pose.rotation, pose.position
    texel = extent / texture.shape[1]
    plane_from_tex = np.array([[texel, 0, -extent / 2 + texel / 2], [0, texel, -extent / 2 + texel / 2], [0, 0, 1]])
    cam_from_plane = np.column_stack([R.T[:, 0], R.T[:, 1], -R.T @ C])
    H = K @ cam_from_plane @ plane_from_tex
    image = cv2.warpPerspective(texture, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    rays = intrinsics.rays(u, v) @ R.T
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = -C[2] / rays[..., 2]  # z-depth: the ray has unit camera-z
    depth = np.where(depth > 0, depth, np.inf).astype(np.float32)
    return CameraFrame(image, pose, intrinsics, stamp, depth)
