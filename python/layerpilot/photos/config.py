"""Settings for mapping from photos; defaults are the values measured in docs/photos.md."""

from __future__ import annotations

from dataclasses import dataclass, field

from layerpilot.config import check_range
from layerpilot.depth.config import MatchConfig, PickConfig


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
class PhotoConfig:
    """Working image width, pair picking, refinement, matching and the map."""

    width: int = 1000  # photos are downscaled to this many pixels across before anything else
    refine: bool = True  # False: raw GNSS/attitude poses (the bench's comparison)
    refinement: RefineConfig = field(default_factory=RefineConfig)
    # Survey photos overlap by 60-70 %: baselines are a third of the flying height.
    pick: PickConfig = field(default_factory=lambda: PickConfig(
        history=4, min_baseline_ratio=0.1, max_baseline_ratio=0.5, target_baseline_ratio=0.3, max_depth=1000.0,
        min_sharpness=0.0))
    match: MatchConfig = field(default_factory=lambda: MatchConfig(
        scale=0.5, num_disparities=240, block_size=9, uniqueness_ratio=5, speckle_window=50, speckle_range=16,
        max_disparity_step=0.0, min_depth=5.0, max_depth=200.0))
    resolution: float = 0.5  # voxel size of the map, metres

    def __post_init__(self) -> None:
        check_range("width", self.width, 64)
        check_range("resolution", self.resolution, 0.01)
