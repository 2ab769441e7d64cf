"""Depth from a moving camera: frame picking, rectification from known poses,
semi-global matching, filtering, and map-frame point clouds.

The camera convention is OpenCV's (x right, y down, z forward); a frame's pose
is the 4x4 transform map <- camera (ENU map frame, metres).
"""

from layerpilot.depth.config import DepthConfig, MatchConfig, PickConfig
from layerpilot.depth.frames import Frame, PointCloud
from layerpilot.depth.picking import FramePicker, PickResult
from layerpilot.depth.rectify import RectifiedPair, rectify
from layerpilot.depth.source import DepthSource, GroundTruthDepth, StereoDepth, make_source
from layerpilot.depth.stereo import StereoMatcher

__all__ = [
    "DepthConfig", "MatchConfig", "PickConfig", "Frame", "PointCloud", "FramePicker", "PickResult",
    "RectifiedPair", "rectify", "DepthSource", "GroundTruthDepth", "StereoDepth", "StereoMatcher", "make_source",
]
