"""Settings for mapping from photos; defaults are the values measured in docs/photos.md."""

from __future__ import annotations

from dataclasses import dataclass, field

from layerpilot.config import check_range
from layerpilot.depth.config import AdjustConfig, MatchConfig, PickConfig, RefineConfig


POSES = ("adjusted", "refined", "raw")


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
    window: int = 10  # live: photos adjusted with each new one (the nearest to it, itself included)
    kept: int = 48  # live: photos held to choose them from (memory: about 6 MB each at 1000 px)

    def __post_init__(self) -> None:
        check_range("width", self.width, 64)
        if self.poses not in POSES:
            raise ValueError(f"poses: {self.poses!r} is not one of {', '.join(POSES)}")
        check_range("resolution", self.resolution, 0.01)
        check_range("window", self.window, 2)
        check_range("kept", self.kept, self.window)
