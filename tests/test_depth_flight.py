"""Stereo depth on a short rendered flight over the default forest, scored against the renderer's depth."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.depth import GroundTruthDepth, StereoDepth
from layerpilot.depth.config import preset_for
from layerpilot.depth.evaluate import score
from layerpilot.eval.fixtures import sideways_flight, terrain_scene_depth
from layerpilot.map import VoxelMap
from layerpilot.camera import CameraConfig
from layerpilot.sim import Renderer, World, WorldConfig


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


def test_a_sharper_camera_pairs_whatever_a_coarser_one_pairs(world):
    """Frames 5 m apart at 40 m and pitch 60 (baseline 0.11 x the scene depth, the spacing of a
    default-speed flight at 1 frame/s): the 640 px preset once refused them all as baseline_long
    while the 320 px one paired them. Both cameras now pair the same frames, and 640 gives more points."""
    runs = {}
    for size in ((320, 240), (640, 480)):
        with Renderer(world, CameraConfig(width=size[0], height=size[1], pitch_deg=60.0)) as r:
            frames = sideways_flight(r, (-60.0, 70.0), heading_deg=20.0, altitude=40.0, pitch_deg=60.0,
                                     speed=10.0, frames=4, period=0.5)
        config = preset_for(size[0], frames[0].intrinsics.fx)
        source = StereoDepth(config, scene_depth=terrain_scene_depth(world))
        clouds = [source.push(f) for f in frames]
        rel = np.concatenate([score(c, f, scale=config.match.scale).rel_errors
                              for c, f in zip(clouds, frames) if c is not None])
        runs[size[0]] = clouds, source.stats(), float((rel <= 0.05).mean())
    (low, low_stats, low_precision), (high, high_stats, high_precision) = runs[320], runs[640]
    assert low_stats == high_stats == {"pairs": 3, "skipped_no_history": 1}
    assert all(len(h) > len(lo) for lo, h in zip(low[1:], high[1:]))
    assert min(low_precision, high_precision) >= 0.95, (low_precision, high_precision)


def test_search_range_and_baseline_window_follow_the_focal_length():
    """The window in scene-depth ratios is the same for every camera (a longer focal length may take
    shorter baselines); the search range holds the near points at the longest baseline."""
    low, high = preset_for(320), preset_for(640)
    assert high.pick.max_baseline_ratio == low.pick.max_baseline_ratio
    assert high.pick.target_baseline_ratio == low.pick.target_baseline_ratio
    assert high.pick.min_baseline_ratio < low.pick.min_baseline_ratio
    for width, fx in ((320, 160.0), (640, 320.0), (640, 554.3), (1280, 640.0)):
        c = preset_for(width, fx)
        f_match = fx * c.match.scale
        assert c.match.num_disparities >= 2.5 * f_match * c.pick.max_baseline_ratio
        assert c.pick.min_baseline_ratio * f_match == pytest.approx(9.6) or c.pick.min_baseline_ratio == 0.06
