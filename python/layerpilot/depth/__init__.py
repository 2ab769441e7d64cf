"""Depth from a moving camera: frame picking, rectification from known poses,
semi-global matching, filtering, and map-frame point clouds.

Frames in are ``layerpilot.geometry.CameraFrame`` (OpenCV camera axes, pose camera ->
map, ENU metres); clouds out are ``layerpilot.geometry.PointCloud``.
"""

from layerpilot.depth.config import DepthConfig, MatchConfig, PickConfig
from layerpilot.depth.picking import FramePicker, PickResult
from layerpilot.depth.rectify import RectifiedPair, rectify
from layerpilot.depth.source import DepthSource, GroundTruthDepth, StereoDepth, make_source
from layerpilot.depth.stereo import StereoMatcher

__all__ = [
    "DepthConfig", "MatchConfig", "PickConfig", "FramePicker", "PickResult",
    "RectifiedPair", "rectify", "DepthSource", "GroundTruthDepth", "StereoDepth", "StereoMatcher", "make_source",
]
