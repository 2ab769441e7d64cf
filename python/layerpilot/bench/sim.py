"""`layerpilot bench sim`: rendering speed along a survey path, with and without frustum culling."""

from __future__ import annotations

import json
import math
import time

import numpy as np

from layerpilot.mission.footprint import footprint_width
from layerpilot.mission.patterns import Region, survey_lines
from layerpilot.camera import CameraConfig
from layerpilot.sim.world import World, WorldConfig

TARGET_FPS = 8.0


def survey_poses(world: World, count: int, height_above_ground: float = 30.0) -> list[tuple[np.ndarray, float]]:
    """``count`` vehicle poses (position, yaw) spread along a lawnmower path over the world."""
    half = footprint_width(CameraConfig(), height_above_ground) / 2
    wp = survey_lines(Region.disc((0.0, 0.0), 0.4 * world.config.size), 0.0, 0.0, (-half, half), 0.3, sideways=False)
    seg = np.diff(wp[:, :2], axis=0)
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*seg.T))])
    poses = []
    for s in np.linspace(0.0, cum[-1], count, endpoint=False):
        k = min(np.searchsorted(cum, s, side="right") - 1, len(seg) - 1)
        x, y = wp[k, :2] + seg[k] * (s - cum[k]) / max(cum[k + 1] - cum[k], 1e-9)
        yaw = math.atan2(seg[k][1], seg[k][0])
        poses.append((np.array([x, y, float(world.terrain_height(x, y)) + height_above_ground]), yaw))
    return poses


def _fps(world: World, camera: CameraConfig, poses, cull: bool) -> tuple[float, str, float]:
    from layerpilot.sim.render import Renderer

    with Renderer(world, camera, cull=cull) as r:
        r.render_vehicle(*poses[0])  # shader compilation and first upload
        tiles = 0
        t0 = time.perf_counter()
        for position, yaw in poses:
            r.render_vehicle(position, yaw)
            tiles += r.last_tiles_drawn
        elapsed = time.perf_counter() - t0
        return len(poses) / elapsed, r.renderer_name, tiles / len(poses)


def main(frames: int, seed: int) -> int:
    if frames < 1:
        raise ValueError(f"frames must be >= 1, got {frames}")
    t0 = time.perf_counter()
    world = World(WorldConfig(seed=seed))
    build_s = time.perf_counter() - t0
    s = world.stats()
    print(f"world seed {seed}: {s['size_m']:g} m square, {s['trees']} trees, {s['triangles']} triangles in "
          f"{s['tiles']} tiles, built in {build_s:.2f} s")
    poses = survey_poses(world, frames)
    result = {"frames": frames, "triangles": s["triangles"], "target_fps": TARGET_FPS}
    for w, h in ((640, 480), (320, 240)):
        fps, name, tiles = _fps(world, CameraConfig(width=w, height=h), poses, cull=True)
        result[f"fps_{w}x{h}"] = round(fps, 2)
        result["renderer"] = name
        print(f"{w}x{h}: {fps:6.1f} frames/s ({tiles:.1f} of {s['tiles']} tiles drawn)  "
              f"{fps / TARGET_FPS:.2f}x the {TARGET_FPS:g} fps target")
    fps_all, _, _ = _fps(world, CameraConfig(), poses, cull=False)
    result["fps_640x480_no_culling"] = round(fps_all, 2)
    result["culling_speedup"] = round(result["fps_640x480"] / fps_all, 2)
    print(f"640x480 drawing every tile (reference): {fps_all:6.1f} frames/s; culling is "
          f"{result['culling_speedup']:.2f}x faster")
    print(json.dumps(result))
    return 0
