"""The depth service: camera frames in, map-frame point clouds out, with the mission's depth source.

One place chooses the source and its settings, so the live depth node and the lock-step
evaluator make the same clouds: two-view stereo with the measured preset for the image
width and focal length (chosen on the first frame), or the frame's own depth (simulator, RGB-D).
Stereo refines the poses of its pairs from the images first (``refine``, on by default;
``depth.live``): a real drone's reported poses are too coarse for two-view stereo; each cloud's height
is then fitted to the flight's earlier clouds (``register_height``, ``depth.height_registration``), unless its surface
jumps metres from the last clouds' (``check_surface``, ``depth.surface_check``: then it is refused). The vehicle's
telemetry pose stream (``push_pose``) lets it learn the camera clock's offset and read the
priors at the exposure time. Survey photos (``depth.pairs = "survey"``, a photo folder played as the
camera) go through the photo pipeline instead: each bundle-adjusted with its nearest photos as it arrives.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

from layerpilot.config import check_range
from layerpilot.depth.config import DepthConfig, preset_for
from layerpilot.depth.downscale import limit_pixels, processing_intrinsics
from layerpilot.depth.height_registration import HeightRegistration
from layerpilot.depth.live import LiveConfig, LiveRefiner
from layerpilot.depth.surface_check import SurfaceCheck
from layerpilot.depth.window import WindowConfig
from layerpilot.geometry import CameraFrame, PointCloud, Pose
from layerpilot.depth.source import DepthSource, GroundTruthDepth, StereoDepth
from layerpilot.photos import PhotoConfig, PhotoStereo


class SurveyDepth:
    """Survey photos as they arrive: each one bundle-adjusted with the photos that overlap it most, then
    matched with its partner (``PhotoStereo.push``, the pipeline of ``layerpilot map images``);
    ``refine = false``: the photos' poses as reported."""

    def __init__(self, refine: bool = True, config: PhotoConfig = PhotoConfig()) -> None:
        self.stereo = PhotoStereo(dataclasses.replace(config, poses="adjusted" if refine else "raw"))
        self.pairs = 0

    def push(self, frame: CameraFrame) -> PointCloud | None:
        result = self.stereo.push(limit_pixels(frame, self.stereo.config.width))
        self.pairs += result is not None
        return None if result is None else result.cloud

    def stats(self) -> dict[str, float]:
        return {"pairs": self.pairs, **{f"skipped_{k}": v for k, v in sorted(self.stereo.skipped.items())}}


@dataclass(frozen=True)
class DepthServiceConfig:
    """The ``[depth]`` table of a mission file."""

    source: Literal["stereo", "ground_truth"] = "stereo"
    pairs: Literal["auto", "video", "survey"] = "auto"  # stereo: frames a second apart, or survey photos
    # (60-70 % overlap, ``photos.PhotoConfig``: windows of photos bundle-adjusted); auto: survey for a photo folder
    max_depth: float = 100.0  # m: ground-truth pixels beyond are dropped; the map's max range for the clouds
    stride: int = 2  # ground truth: every stride-th pixel in each direction
    queue_size: int = 4  # frames waiting in the live node; the oldest is dropped beyond
    refine: bool = True  # stereo: refine the pairs' poses from the images (false: use the reported poses as they are)
    register_height: bool = True  # stereo: fit each cloud's height to the flight's earlier clouds (GNSS's vertical wander)
    check_surface: bool = True  # stereo: refuse a cloud whose surface jumps from the last clouds' (a wrong pose or scale)
    window: int = 20  # keyframes adjusted together
    gnss_sigma_h: float = 2.0  # m: how far the reported position may be off, per horizontal axis ...
    gnss_sigma_v: float = 4.0  # ... and vertically
    gnss_delta_sigma_h: float = 0.2  # m: how far the reported displacement between frames a second apart may be off ...
    gnss_delta_sigma_v: float = 0.3  # ... vertically (GNSS's wandering error is common to both frames)
    yaw_sigma_deg: float = 10.0  # deg: the reported heading's prior (weak: its bias shows in the GNSS track)
    max_clock_offset: float = 0.5  # s: the camera clock's offset from the telemetry's is searched within this

    def __post_init__(self) -> None:
        check_range("depth.max_depth", self.max_depth, 1.0, 10_000.0)
        check_range("depth.stride", self.stride, 1, 64)
        check_range("depth.queue_size", self.queue_size, 1, 1000)
        check_range("depth.window", self.window, 2, 500)
        check_range("depth.gnss_sigma_h", self.gnss_sigma_h, 0.01, 1000.0)
        check_range("depth.gnss_sigma_v", self.gnss_sigma_v, 0.01, 1000.0)
        check_range("depth.gnss_delta_sigma_h", self.gnss_delta_sigma_h, 0.001, 1000.0)
        check_range("depth.gnss_delta_sigma_v", self.gnss_delta_sigma_v, 0.001, 1000.0)
        check_range("depth.yaw_sigma_deg", self.yaw_sigma_deg, 0.01, 180.0)
        check_range("depth.max_clock_offset", self.max_clock_offset, 0.0, 10.0)

    def live(self, gimbal: bool = True) -> LiveConfig:
        """The live refinement's settings."""
        window = dataclasses.replace(WindowConfig(), size=self.window, gnss_sigma_h=self.gnss_sigma_h,
                                     gnss_sigma_v=self.gnss_sigma_v, delta_sigma_h=self.gnss_delta_sigma_h,
                                     delta_sigma_v=self.gnss_delta_sigma_v, yaw_sigma_deg=self.yaw_sigma_deg)
        return LiveConfig(window=window, max_offset=self.max_clock_offset, gimbal=gimbal)


class DepthService:
    """Frames -> clouds; counts frames, clouds and the source's reasons for skipping.

    ``gimbal``: the camera keeps only the vehicle's heading (``camera.gimbal``), which is how the
    telemetry's poses turn into camera poses."""

    def __init__(self, cfg: DepthServiceConfig, gimbal: bool = True) -> None:
        self.cfg = cfg
        video = cfg.source == "stereo" and cfg.pairs != "survey"
        self.source: DepthSource | None = (GroundTruthDepth(cfg.max_depth, cfg.stride) if cfg.source == "ground_truth"
                                           else SurveyDepth(cfg.refine) if not video else None)
        self.refiner = LiveRefiner(cfg.live(gimbal)) if video and cfg.refine else None
        self.height = HeightRegistration() if video and cfg.register_height else None
        self.surface = SurfaceCheck() if video and cfg.check_surface else None
        self.frames = 0
        self.clouds = 0
        self._reported: list[tuple[float, Pose]] = []  # without refinement: the poses the clouds were placed with

    def push_pose(self, stamp: float, pose: Pose) -> None:
        """One pose of the vehicle's telemetry stream (body -> map, telemetry clock), in order of arrival."""
        if self.refiner is not None:
            self.refiner.push_pose(stamp, pose)

    def push(self, frame: CameraFrame) -> PointCloud | None:
        """The frame's cloud, or None (no partner yet, skipped, or no points)."""
        if self.source is None:  # stereo presets depend on the size matched at: chosen on the first frame
            k = processing_intrinsics(frame.intrinsics)
            self.source = StereoDepth(preset_for(k.width, k.fx), refiner=self.refiner)
        self.frames += 1
        if self.refiner is None:
            self._reported.append((frame.stamp, frame.pose))
        cloud = self.source.push(frame)
        if cloud is None or len(cloud) == 0:
            return None
        if self.surface is not None and not self.surface.accepts(
                cloud, self.height.correction if self.height is not None else 0.0):
            return None  # counted in the check's stats
        if self.height is not None:
            cloud = self.height.register(cloud)
        self.clouds += 1
        return cloud

    def trajectory(self) -> list[tuple[float, Pose]]:
        """The camera poses the clouds were placed with, [(stamp, camera -> map)]: the refined keyframes'
        latest estimates, or without refinement every frame's reported pose; lifted by the height registration."""
        placed = self.refiner.trajectory() if self.refiner is not None else list(self._reported)
        return self.height.corrected(placed) if self.height is not None else placed

    def stats(self) -> dict[str, float]:
        source = self.source.stats() if self.source is not None else {}
        height = self.height.stats() if self.height is not None else {}
        checked = self.surface.stats() if self.surface is not None else {}
        return {"frames": self.frames, "clouds": self.clouds, **source, **height, **checked}
