"""The depth service: camera frames in, map-frame point clouds out, with the mission's depth source.

One place chooses the source and its settings, so the live depth node and the lock-step
evaluator make the same clouds: two-view stereo with the measured preset for the image
width and focal length (chosen on the first frame), or the frame's own depth (simulator, RGB-D).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from layerpilot.config import check_range
from layerpilot.depth.config import DepthConfig, preset_for
from layerpilot.depth.downscale import processing_intrinsics
from layerpilot.geometry import CameraFrame, PointCloud
from layerpilot.depth.source import DepthSource, GroundTruthDepth, StereoDepth


@dataclass(frozen=True)
class DepthServiceConfig:
    """The ``[depth]`` table of a mission file."""

    source: Literal["stereo", "ground_truth"] = "stereo"
    max_depth: float = 100.0  # m: ground-truth pixels beyond are dropped; the map's max range for the clouds
    stride: int = 2  # ground truth: every stride-th pixel in each direction
    queue_size: int = 4  # frames waiting in the live node; the oldest is dropped beyond

    def __post_init__(self) -> None:
        check_range("depth.max_depth", self.max_depth, 1.0, 10_000.0)
        check_range("depth.stride", self.stride, 1, 64)
        check_range("depth.queue_size", self.queue_size, 1, 1000)


def stereo_preset(width: int, fx: float | None = None) -> DepthConfig:
    """The stereo settings for an image width and focal length in pixels (default: a 90 deg camera):
    what the service uses and what survey speeds assume."""
    return preset_for(width, fx)


class DepthService:
    """Frames -> clouds; counts frames, clouds and the source's reasons for skipping."""

    def __init__(self, cfg: DepthServiceConfig) -> None:
        self.cfg = cfg
        self.source: DepthSource | None = (GroundTruthDepth(cfg.max_depth, cfg.stride)
                                           if cfg.source == "ground_truth" else None)
        self.frames = 0
        self.clouds = 0

    def push(self, frame: CameraFrame) -> PointCloud | None:
        """The frame's cloud, or None (no partner yet, skipped, or no points)."""
        if self.source is None:  # stereo presets depend on the size matched at: chosen on the first frame
            k = processing_intrinsics(frame.intrinsics)
            self.source = StereoDepth(stereo_preset(k.width, k.fx))
        self.frames += 1
        cloud = self.source.push(frame)
        if cloud is None or len(cloud) == 0:
            return None
        self.clouds += 1
        return cloud

    def stats(self) -> dict[str, int]:
        source = self.source.stats() if self.source is not None else {}
        return {"frames": self.frames, "clouds": self.clouds, **source}
