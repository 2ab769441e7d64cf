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
    lr_max_diff: float = 1.0  # left-right consistency tolerance in pixels
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
        check_range("lr_max_diff", self.lr_max_diff, 0.0)
        check_range("min_texture", self.min_texture, 0.0)
        check_range("max_disparity_step", self.max_disparity_step, 0.0)
        check_range("edge_margin", self.edge_margin, 0)
        check_range("max_depth", self.max_depth, self.min_depth)


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
    640: MatchConfig(scale=0.75, block_size=5, edge_margin=6),
    320: MatchConfig(scale=1.0, block_size=3, min_texture=0.5, edge_margin=4),
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
