"""A stereo pair larger than the presets' processing size is downscaled before matching: a 12.6 MP pair
costs what a 640 px pair costs and maps the same scene as well, with rays and poses unchanged."""

from __future__ import annotations

import dataclasses
import time

import cv2
import numpy as np

from layerpilot.depth.downscale import MAX_WIDTH, limit_pixels, processing_intrinsics
from layerpilot.depth.evaluate import score
from layerpilot.depth.source import MAX_DEPTH_POINTS, GroundTruthDepth
from layerpilot.eval.fixtures import sideways_flight
from layerpilot.geometry import CameraFrame, CameraIntrinsics, Pose
from layerpilot.mission.depth_service import DepthService, DepthServiceConfig
from layerpilot.camera import CameraConfig
from layerpilot.sim import Renderer, World, WorldConfig


def upscaled(frame: CameraFrame, width: int, height: int) -> CameraFrame:
    """The same view as a camera of width x height would see it (a drone photo's size)."""
    k = frame.intrinsics.scaled(width / frame.intrinsics.width)
    assert k.size == (width, height), k
    return dataclasses.replace(frame, intrinsics=k,
                               image=cv2.resize(frame.image, k.size, interpolation=cv2.INTER_CUBIC),
                               depth=cv2.resize(frame.depth, k.size, interpolation=cv2.INTER_NEAREST))


def test_a_wide_frame_is_resized_to_the_processing_width_with_the_same_rays():
    k = CameraIntrinsics(2000.0, 2000.0, 2047.5, 1535.5, 4096, 3072)
    frame = CameraFrame(np.zeros((3072, 4096, 3), np.uint8), Pose(np.zeros(3)), k, 1.0,
                        np.full((3072, 4096), 7.0, np.float32))
    small = limit_pixels(frame)
    assert small.intrinsics.size == (MAX_WIDTH, 480) and small.image.shape == (480, MAX_WIDTH, 3)
    assert small.depth.shape == (480, MAX_WIDTH) and np.all(small.depth == 7.0)
    assert small.pose is frame.pose and small.stamp == frame.stamp
    # a point seen at pixel (u, v) of the big frame is seen at the same place of the small one
    points = np.array([[1.0, -2.0, 10.0], [-3.0, 0.5, 20.0], [0.0, 0.0, 5.0]])
    (uv_big, z_big), (uv_small, z_small) = frame.project(points), small.project(points)
    np.testing.assert_allclose((uv_big + 0.5) * MAX_WIDTH / 4096 - 0.5, uv_small, atol=1e-9)
    np.testing.assert_allclose(z_big, z_small)
    narrow = dataclasses.replace(frame, image=np.zeros((480, 640, 3), np.uint8), depth=None,
                                 intrinsics=CameraIntrinsics(320.0, 320.0, 319.5, 239.5, 640, 480))
    assert limit_pixels(narrow) is narrow and processing_intrinsics(narrow.intrinsics) is narrow.intrinsics


def test_a_12_mp_pair_costs_what_a_640_pixel_pair_costs():
    """Two 4096x3072 frames 1.8 m apart looking down from 30 m, matched as a 640x480 pair is."""
    world = World(WorldConfig())
    with Renderer(world, CameraConfig(width=640, height=480, pitch_deg=90.0)) as r:
        frames = sideways_flight(r, (40.0, -60.0), heading_deg=0.0, altitude=30.0, pitch_deg=90.0,
                                 speed=3.6, frames=2, period=0.5)
    results = {}
    for name, pair in (("640", frames), ("4096", [upscaled(f, 4096, 3072) for f in frames])):
        service = DepthService(DepthServiceConfig())
        assert service.push(pair[0]) is None  # no partner yet
        t = time.perf_counter()
        cloud = service.push(pair[1])
        results[name] = (time.perf_counter() - t, cloud)
    (t_small, small), (t_big, big) = results["640"], results["4096"]
    assert small is not None and big is not None
    assert len(big) > 0.8 * len(small), (len(big), len(small))
    s = score(big, limit_pixels(upscaled(frames[1], 4096, 3072)), scale=0.75)
    assert s.precision >= 0.9 and s.median_rel_error < 0.03, s
    # the matcher sees 640x480 either way: the resize is all the big pair adds (generous for a loaded machine)
    assert t_big < 3 * t_small + 1.0, (t_big, t_small)


def test_a_huge_depth_image_is_strided_to_the_point_cap() -> None:
    """The ground-truth source bounds its cloud before back-projecting: a 12.6 MP depth image gives at most
    MAX_DEPTH_POINTS points; a 640x480 one keeps every pixel at stride 1 (the evaluation's truth is unchanged)."""
    def frame(w: int, h: int) -> CameraFrame:
        return CameraFrame(np.zeros((h, w, 3), np.uint8), Pose(np.zeros(3)), CameraConfig(width=w, height=h).intrinsics,
                           0.0, depth=np.full((h, w), 40.0, np.float32))

    huge = GroundTruthDepth(100.0, stride=2).push(frame(4096, 3072))
    assert 0.8 * MAX_DEPTH_POINTS < len(huge) <= MAX_DEPTH_POINTS
    assert len(GroundTruthDepth(100.0, stride=1).push(frame(640, 480))) == 640 * 480
