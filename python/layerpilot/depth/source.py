"""Depth sources: whatever turns frames into map-frame point clouds.

A node holds one ``DepthSource`` and calls ``push(frame)`` for every camera
frame; it gets a ``PointCloud`` or ``None`` (frame skipped, reason counted in
``stats()``). ``StereoDepth`` estimates depth from two views; ``GroundTruthDepth``
back-projects a depth image that comes with the frame (simulator or RGB-D), the
ideal reference for the map.
"""

from __future__ import annotations

import math
from typing import Callable, Protocol

import numpy as np

from layerpilot.depth.config import DepthConfig
from layerpilot.depth.backproject import camera_points_to_cloud
from layerpilot.depth.downscale import MAX_WIDTH, limit_pixels
from layerpilot.depth.live import LiveRefiner
from layerpilot.depth.picking import FramePicker
from layerpilot.depth.stereo import StereoMatcher
from layerpilot.geometry import CameraFrame, PointCloud


class DepthSource(Protocol):
    def push(self, frame: CameraFrame) -> PointCloud | None: ...

    def stats(self) -> dict[str, int]: ...


class StereoDepth:
    """Two-view stereo: pick a partner for each new frame, match, filter, publish.

    Frames wider than ``max_width`` are downscaled to it first (``depth.downscale``): what a
    pair costs is bounded whatever the camera sends, and the picker's history holds small frames.
    """

    def __init__(self, config: DepthConfig = DepthConfig(),
                 scene_depth: Callable[[CameraFrame], float] | None = None, max_width: int = MAX_WIDTH,
                 refiner: LiveRefiner | None = None) -> None:
        self.picker = FramePicker(config.pick, scene_depth)
        self.matcher = StereoMatcher(config.match)
        self.max_width = max_width
        self.refiner = refiner  # None: the frames' poses are used as they come

    def push(self, frame: CameraFrame) -> PointCloud | None:
        frame = limit_pixels(frame, self.max_width)
        pick = self.picker.push(frame)
        if pick.partner is None:
            return None
        ref, partner = frame, pick.partner
        if self.refiner is not None:
            if (refined := self.refiner.refine(frame, partner)) is None:
                return None  # the reason is counted in the refiner's stats
            ref, partner = refined
        cloud, _ = self.matcher.cloud(ref, partner)
        return cloud

    def stats(self) -> dict[str, float]:
        refined = self.refiner.stats() if self.refiner is not None else {}
        return {"pairs": self.picker.pairs, **{f"skipped_{k}": v for k, v in sorted(self.picker.skipped.items())},
                **refined}


MAX_DEPTH_POINTS = 640 * 480  # a depth image gives at most this many points: a larger one is strided more


class GroundTruthDepth:
    """Back-project ``frame.depth`` (z-depth, metres); pixels beyond ``max_depth`` are dropped.

    The cost is bounded before it is paid: a frame whose every ``stride``-th pixel would give more than
    ``MAX_DEPTH_POINTS`` points is read with the smallest larger stride that keeps within it (a 12.6 MP
    depth image: stride 7, 257 k points, instead of 3.1 M at stride 2)."""

    def __init__(self, max_depth: float = 100.0, stride: int = 1) -> None:
        if stride < 1:
            raise ValueError(f"stride: must be >= 1, got {stride}")
        self.max_depth = max_depth
        self.stride = stride
        self.frames = 0
        self.skipped_no_depth = 0

    def push(self, frame: CameraFrame) -> PointCloud | None:
        if frame.depth is None:
            self.skipped_no_depth += 1
            return None
        h, w = frame.depth.shape[:2]
        s = max(self.stride, math.ceil(math.sqrt(h * w / MAX_DEPTH_POINTS)))
        depth = frame.depth[::s, ::s]
        valid = depth > 0  # NaN and inf fail one of the two comparisons
        valid &= depth <= self.max_depth
        flat = np.flatnonzero(valid)  # one pass over the pixels; every frame of a mission comes here
        v, u = np.divmod(flat, depth.shape[1])
        z = depth.ravel()[flat].astype(np.float64)
        k = frame.intrinsics
        cam = np.empty((len(flat), 3))  # rays(u, v) * z, with each row's and column's ray part computed once
        np.multiply(((np.arange(0, k.width, s, dtype=np.float64) - k.cx) / k.fx)[u], z, out=cam[:, 0])
        np.multiply(((np.arange(0, k.height, s, dtype=np.float64) - k.cy) / k.fy)[v], z, out=cam[:, 1])
        cam[:, 2] = z
        self.frames += 1
        return camera_points_to_cloud(frame, cam, frame.image[::s, ::s].reshape(-1, 3)[flat])

    def stats(self) -> dict[str, int]:
        return {"frames": self.frames, "skipped_no_depth": self.skipped_no_depth}


def make_source(kind: str, config: DepthConfig = DepthConfig(),
                scene_depth: Callable[[CameraFrame], float] | None = None) -> DepthSource:
    """The node's depth source by name: ``"stereo"`` or ``"ground_truth"``."""
    if kind == "stereo":
        return StereoDepth(config, scene_depth)
    if kind == "ground_truth":
        return GroundTruthDepth(config.match.max_depth)
    raise ValueError(f"kind: expected 'stereo' or 'ground_truth', got {kind!r}")
