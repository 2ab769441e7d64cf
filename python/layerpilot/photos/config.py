"""Settings for mapping from photos; defaults are the values measured in docs/photos.md."""

from __future__ import annotations

from dataclasses import dataclass, field

from layerpilot.config import check_range
from layerpilot.depth.config import MatchConfig, PickConfig


POSES = ("adjusted", "refined", "raw")


@dataclass(frozen=True)
class RefineConfig:
    """Relative pose from the images (see docs/photos.md, "Pose refinement")."""

    features: int = 8000  # SIFT keypoints per image at the working scale
    ratio: float = 0.9  # Lowe's ratio test
    ransac_px: float = 1.0  # essential-matrix RANSAC threshold, pixels at the working scale
    min_inliers: int = 60
    min_inlier_ratio: float = 0.35  # RANSAC inliers / ratio-test matches; below it the geometry is a guess
    max_rotation_deg: float = 5.0  # images and GNSS/attitude may disagree by this much ...
    max_direction_deg: float = 25.0  # ... and the baseline directions by this much
    flip_heading: bool = True  # a baseline direction off by 180 +- max_direction_deg: the heading is, correct it

    def __post_init__(self) -> None:
        check_range("features", self.features, 100)
        check_range("ratio", self.ratio, 0.1, 1.0)
        check_range("ransac_px", self.ransac_px, 0.1)
        check_range("min_inliers", self.min_inliers, 8)
        check_range("min_inlier_ratio", self.min_inlier_ratio, 0.0, 1.0)
        check_range("max_rotation_deg", self.max_rotation_deg, 0.0, 90.0)
        check_range("max_direction_deg", self.max_direction_deg, 0.0, 180.0)


@dataclass(frozen=True)
class AdjustConfig:
    """Bundle adjustment of all photos (see docs/photos.md, "Bundle adjustment")."""

    overlap_ratio: float = 1.0  # photos whose centres are within this x the flying height are matched
    guide_px: float = 25.0  # matches farther from the GNSS/attitude epipolar line are dropped (0: off)
    ransac_px: float = 1.0  # essential-matrix RANSAC threshold per pair, pixels at the working scale
    min_inliers: int = 40
    min_inlier_ratio: float = 0.1  # tracks through three and more photos reject the remaining outliers
    max_rotation_deg: float = 10.0  # a pair whose images disagree more with the attitudes is not linked
    max_direction_deg: float = 30.0
    min_track: int = 3  # photos a track must be seen in (two-view tracks only add noise)
    pixel_sigma: float = 1.0  # reprojection error scale, pixels at the working scale
    gnss_sigma_h: float = 0.5  # GNSS position prior, metres
    gnss_sigma_v: float = 0.2  # GPS altitude follows the barometric height within 0.1 m
    tilt_sigma_deg: float = 1.0  # attitude prior on the camera's tilt (the stabilised gimbal's pitch and roll)
    yaw_sigma_deg: float = 10.0  # ... and on its heading (after the heading vote; the compass is poor)
    focal_sigma: float = 0.0  # > 0: also fit one focal-length factor with this prior sigma
    distortion_sigma: float = 0.2  # > 0: also fit radial distortion k1, k2 (prior 0 with this sigma)
    loss: str = "soft_l1"
    loss_scale: float = 2.0  # residuals (in sigmas) beyond this are down-weighted
    max_evaluations: int = 60

    def __post_init__(self) -> None:
        check_range("overlap_ratio", self.overlap_ratio, 0.0)
        check_range("guide_px", self.guide_px, 0.0)
        check_range("ransac_px", self.ransac_px, 0.1)
        check_range("min_inliers", self.min_inliers, 8)
        check_range("min_inlier_ratio", self.min_inlier_ratio, 0.0, 1.0)
        check_range("max_rotation_deg", self.max_rotation_deg, 0.0, 180.0)
        check_range("max_direction_deg", self.max_direction_deg, 0.0, 180.0)
        check_range("min_track", self.min_track, 2)
        for name in ("pixel_sigma", "gnss_sigma_h", "gnss_sigma_v", "tilt_sigma_deg", "yaw_sigma_deg", "loss_scale"):
            check_range(name, getattr(self, name), 1e-6)
        check_range("focal_sigma", self.focal_sigma, 0.0)
        check_range("distortion_sigma", self.distortion_sigma, 0.0)
        check_range("max_evaluations", self.max_evaluations, 1)
        if self.loss not in ("linear", "soft_l1", "huber", "cauchy", "arctan"):
            raise ValueError(f"loss: {self.loss!r} is not one of linear, soft_l1, huber, cauchy, arctan")


@dataclass(frozen=True)
class PhotoConfig:
    """Working image width, pair picking, refinement, matching and the map."""

    width: int = 1000  # photos are downscaled to this many pixels across before anything else
    poses: str = "adjusted"  # bundle-adjusted, "refined" per pair, or "raw" GNSS/attitude (the bench compares all)
    refinement: RefineConfig = field(default_factory=RefineConfig)
    adjustment: AdjustConfig = field(default_factory=AdjustConfig)
    # Survey photos overlap by 60-70 %: baselines are a third of the flying height.
    pick: PickConfig = field(default_factory=lambda: PickConfig(
        history=4, min_baseline_ratio=0.1, max_baseline_ratio=0.5, target_baseline_ratio=0.3, max_depth=1000.0,
        min_sharpness=0.0))
    # Nadir photos from tens of metres: a depth beyond 100 m is a mismatch (in the forest they reached 200 m).
    match: MatchConfig = field(default_factory=lambda: MatchConfig(
        scale=0.5, num_disparities=240, block_size=9, uniqueness_ratio=5, speckle_window=50, speckle_range=16,
        max_disparity_step=0.0, min_depth=5.0, max_depth=100.0))
    resolution: float = 0.5  # voxel size of the map, metres

    def __post_init__(self) -> None:
        check_range("width", self.width, 64)
        if self.poses not in POSES:
            raise ValueError(f"poses: {self.poses!r} is not one of {', '.join(POSES)}")
        check_range("resolution", self.resolution, 0.01)
