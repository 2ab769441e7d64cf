"""Stereo depth on a short rendered flight over the default forest, scored against the renderer's depth."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.depth import GroundTruthDepth, StereoDepth
from layerpilot.depth.config import preset_for
from layerpilot.depth.evaluate import score
from layerpilot.eval.fixtures import sideways_flight, terrain_scene_depth
from layerpilot.map import VoxelMap
from layerpilot.sim import CameraConfig, Renderer, World, WorldConfig


@pytest.fixture(scope="module")
def world() -> World:
    return World(WorldConfig())


@pytest.mark.parametrize("size, altitude, pitch", [((320, 240), 40.0, 60.0), ((640, 480), 55.0, 90.0)])
def test_rendered_flight_precision_and_coverage(world, size, altitude, pitch):
    with Renderer(world, CameraConfig(width=size[0], height=size[1], pitch_deg=pitch)) as r:
        frames = sideways_flight(r, (-60.0, 70.0), heading_deg=20.0, altitude=altitude, pitch_deg=pitch,
                                 speed=6.0, frames=6, period=0.5)
    config = preset_for(size[0])
    source = StereoDepth(config, scene_depth=terrain_scene_depth(world))
    rel, coverage = [], []
    for frame in frames:
        cloud = source.push(frame)
        if cloud is None:
            continue
        s = score(cloud, frame, scale=config.match.scale)
        rel.append(s.rel_errors)
        coverage.append(s.coverage)
        np.testing.assert_array_equal(cloud.origin, frame.pose.position)
        assert cloud.stamp == frame.stamp
    stats = source.stats()
    assert stats["pairs"] >= 4 and stats["skipped_no_history"] == 1
    rel = np.concatenate(rel)
    precision = float((rel <= 0.05).mean())
    assert precision >= 0.95, precision
    assert float(np.mean(coverage)) >= 0.6, coverage
    assert float(np.median(rel)) < 0.02


def test_clouds_go_into_the_voxel_map(world):
    with Renderer(world, CameraConfig(width=320, height=240, pitch_deg=90.0)) as r:
        frames = sideways_flight(r, (40.0, -60.0), heading_deg=0.0, altitude=35.0, pitch_deg=90.0,
                                 speed=6.0, frames=3, period=0.5)
    stereo = StereoDepth(preset_for(320), scene_depth=terrain_scene_depth(world))
    truth = GroundTruthDepth(stride=2)
    clouds = [c for c in (stereo.push(f) for f in frames) if c is not None]
    assert clouds
    vmap, ref_map = VoxelMap(resolution=1.0), VoxelMap(resolution=1.0)
    for c in clouds:
        result = vmap.insert(c.points, c.origin, c.colors, c.stamp)
        assert result.points_used == len(c) and result.voxels_occupied > 100
    for f in frames:
        c = truth.push(f)
        ref_map.insert(c.points, c.origin, c.colors, c.stamp)
    # voxels the stereo map calls occupied have an occupied ground-truth voxel at most one voxel away
    occ = vmap.voxels(np.array([-1e3, -1e3, -1e3]), np.array([1e3, 1e3, 1e3]), min_occupancy=0.5)
    offsets = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], np.float32)
    near = np.max([np.nan_to_num(ref_map.occupancy(occ.centers + o), nan=0.0) for o in offsets], axis=0)
    assert len(occ) > 1000 and np.mean(near > 0.5) > 0.95
