"""Depth settings: frame picking and matching. Defaults are the values measured in docs/depth.md."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from layerpilot.config import ConfigError, check_range


@dataclass(frozen=True)
class PickConfig:
    """When two frames make a usable stereo pair (see docs/depth.md, "Frame picking")."""

    history: int = 12  # frames kept to choose a partner from
    min_baseline_ratio: float = 0.03  # baseline / median scene depth
    max_baseline_ratio: float = 0.12
    target_baseline_ratio: float = 0.06  # preferred among the usable partners
    max_rotation_deg: float = 15.0  # relative rotation between the two cameras
    epipole_margin: float = 0.1  # epipole must lie this fraction of the image size outside the image
    min_sharpness: float = 150.0  # variance of the Laplacian of the grey image at <= 320 px width
    ground_z: float = 0.0  # ground height for the altitude-based scene depth estimate
    max_depth: float = 100.0

    def __post_init__(self) -> None:
        check_range("history", self.history, 2)
        check_range("min_baseline_ratio", self.min_baseline_ratio, 1e-4, 1.0)
        check_range("max_baseline_ratio", self.max_baseline_ratio, self.min_baseline_ratio, 1.0)
        check_range("target_baseline_ratio", self.target_baseline_ratio, self.min_baseline_ratio,
                    self.max_baseline_ratio)
        check_range("max_rotation_deg", self.max_rotation_deg, 0.0, 90.0)
        check_range("epipole_margin", self.epipole_margin, 0.0)
        check_range("min_sharpness", self.min_sharpness, 0.0)
        check_range("max_depth", self.max_depth, 1e-3)


@dataclass(frozen=True)
class MatchConfig:
    """Semi-global matching and the filters after it (see docs/depth.md, "Matching")."""

    scale: float = 1.0  # images are resized by this before matching (0.5 halves both sides)
    num_disparities: int = 64  # search range at matching scale, multiple of 16
    block_size: int = 5
    mode: str = "sgbm_3way"  # "sgbm", "sgbm_3way", "hh", "hh4"
    uniqueness_ratio: int = 10  # percent
    speckle_window: int = 100  # pixels at matching scale
    speckle_range: int = 2  # disparity units (OpenCV multiplies by 16)
    lr_check: str = "mirrored"  # left-right consistency: "mirrored" pair matched again, or "sgbm" (its own, one call)
    lr_max_diff: float = 1.0  # left-right consistency tolerance in pixels ("sgbm" rounds it up to whole pixels)
    min_texture: float = 1.0  # grey-level standard deviation in the block around a pixel (0 = off)
    max_disparity_step: float = 1.0  # drop pixels whose 3x3 neighbourhood spans more (0 = off)
    edge_margin: int = 8  # pixels dropped along the border of the valid rectified area
    max_depth: float = 100.0
    min_depth: float = 0.5

    def __post_init__(self) -> None:
        check_range("scale", self.scale, 0.1, 1.0)
        check_range("num_disparities", self.num_disparities, 16, 512)
        if self.num_disparities % 16:
            raise ConfigError(f"num_disparities = {self.num_disparities} must be a multiple of 16")
        if self.block_size % 2 == 0 or not 1 <= self.block_size <= 21:
            raise ConfigError(f"block_size = {self.block_size} must be odd in [1, 21]")
        if self.mode not in ("sgbm", "sgbm_3way", "hh", "hh4"):
            raise ConfigError(f"mode = {self.mode!r}: expected sgbm, sgbm_3way, hh or hh4")
        check_range("uniqueness_ratio", self.uniqueness_ratio, 0, 100)
        check_range("speckle_window", self.speckle_window, 0)
        check_range("speckle_range", self.speckle_range, 0)
        if self.lr_check not in ("mirrored", "sgbm"):
            raise ConfigError(f"lr_check = {self.lr_check!r}: expected mirrored or sgbm")
        check_range("lr_max_diff", self.lr_max_diff, 0.0)
        check_range("min_texture", self.min_texture, 0.0)
        check_range("max_disparity_step", self.max_disparity_step, 0.0)
        check_range("edge_margin", self.edge_margin, 0)
        check_range("max_depth", self.max_depth, self.min_depth)


@dataclass(frozen=True)
class RefineConfig:
    """Relative pose from the images (see docs/photos.md, "Per-pair refinement", and docs/depth.md, "Pose refinement")."""

    detector: str = "sift"  # "sift": keypoints matched by descriptor; "klt": corners of the partner tracked by optical flow
    scale: float = 1.0  # images are resized by this before features are found (pixels come back at full size)
    features: int = 8000  # SIFT keypoints / KLT corners per image at the working scale
    ratio: float = 0.9  # Lowe's ratio test
    ransac_px: float = 1.0  # essential-matrix RANSAC threshold, pixels at the working scale
    min_inliers: int = 60
    min_inlier_ratio: float = 0.35  # RANSAC inliers / ratio-test matches; below it the geometry is a guess
    max_rotation_deg: float = 5.0  # images and GNSS/attitude may disagree by this much ...
    max_direction_deg: float = 25.0  # ... and the baseline directions by this much
    flip_heading: bool = True  # a baseline direction off by 180 +- max_direction_deg: the heading is, correct it
    polish: bool = False  # refine RANSAC's pose on all its inliers (robust Sampson error; docs/depth.md: the live
    # default, 2-5x smaller errors on rendered frames; on the nadir photos with their uncorrected lens it drifts)

    def __post_init__(self) -> None:
        if self.detector not in ("sift", "klt"):
            raise ConfigError(f"detector = {self.detector!r}: expected sift or klt")
        check_range("scale", self.scale, 0.1, 1.0)
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
class DepthConfig:
    pick: PickConfig = field(default_factory=PickConfig)
    match: MatchConfig = field(default_factory=MatchConfig)


# The baseline window is geometry, the same for every camera: a flight's frame spacing (speed over
# frame rate, relative to the scene depth) does not depend on the image size, so a sharper camera must
# accept every pair a coarser one accepts (a 640 px window of 0.04-0.09 threw away the 0.09-0.12 pairs
# the 320 px one kept: 59.5 % mapped instead of 90 %, docs/depth.md). What follows the focal length
# at matching scale, f_m, is in pixels: the shortest baseline gives MIN_DISPARITY px at the median
# depth (a higher-resolution camera may take shorter ones), and the search range holds points
# NEAR_FACTOR x closer than the median at the longest baseline.
PICK = PickConfig(min_baseline_ratio=0.06, max_baseline_ratio=0.12, target_baseline_ratio=0.09)
MIN_DISPARITY = 9.6  # px at matching scale: 0.06 x f_m = 160 px (320 wide, 90 deg)
NEAR_FACTOR = 2.5  # 48 disparities at 320 px: 2.5 x 0.12 x 160 = 48

# Measured matcher settings per image width (docs/depth.md); num_disparities is derived.
MATCH = {
    640: MatchConfig(scale=0.75, block_size=5, edge_margin=6, lr_check="sgbm"),
    320: MatchConfig(scale=1.0, block_size=3, min_texture=0.5, edge_margin=4, lr_check="sgbm"),
}


def search_range(f_match: float, max_ratio: float) -> int:
    """Disparities (a multiple of 16) that hold points NEAR_FACTOR x closer than the median depth."""
    return int(16 * math.ceil(NEAR_FACTOR * f_match * max_ratio / 16 - 1e-9))


def preset_for(width: int, fx: float | None = None) -> DepthConfig:
    """Settings for an image ``width`` and focal length ``fx`` in pixels (default: a 90 deg camera).

    The matcher settings are the measured ones of the nearest width; the baseline window and the
    search range follow the focal length at matching scale (see the rule above)."""
    f_match = (width / 2 if fx is None else fx) * (match := MATCH[min(MATCH, key=lambda w: abs(w - width))]).scale
    min_ratio = min(MIN_DISPARITY / f_match, PICK.min_baseline_ratio)
    pick = dataclasses.replace(PICK, min_baseline_ratio=min_ratio)
    return DepthConfig(pick, dataclasses.replace(match, num_disparities=search_range(f_match, pick.max_baseline_ratio)))
