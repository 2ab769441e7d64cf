"""Frames larger than the stereo presets' processing size are downscaled before anything else.

Matching cost grows with the pixels and with the search range, which follows the focal
length in pixels: both grow with the width, so a drone photo's pair costs seconds and
gigabytes at full size. The presets are
measured up to ``MAX_WIDTH`` pixels wide; a wider frame is resized to it (image by area
averaging, depth by nearest neighbour so that no depth is invented between two surfaces)
and its intrinsics scaled with it, so that rays and poses stay what they were.
"""

from __future__ import annotations

import dataclasses

import cv2

from layerpilot.depth.config import MATCH
from layerpilot.geometry import CameraFrame, CameraIntrinsics

MAX_WIDTH = max(MATCH)  # pixels: the widest measured preset


def processing_intrinsics(k: CameraIntrinsics, max_width: int = MAX_WIDTH) -> CameraIntrinsics:
    """The intrinsics a frame with ``k`` is matched at: ``k`` itself, or scaled down to ``max_width``."""
    if max_width < 1:
        raise ValueError(f"max_width: must be >= 1, got {max_width}")
    return k if k.width <= max_width else k.scaled(max_width / k.width)


def limit_pixels(frame: CameraFrame, max_width: int = MAX_WIDTH) -> CameraFrame:
    """``frame`` if it is at most ``max_width`` wide, else the same view resized to that width."""
    k = processing_intrinsics(frame.intrinsics, max_width)
    if k is frame.intrinsics:
        return frame
    image = cv2.resize(frame.image, k.size, interpolation=cv2.INTER_AREA)
    depth = None if frame.depth is None else cv2.resize(frame.depth, k.size, interpolation=cv2.INTER_NEAREST)
    return dataclasses.replace(frame, image=image, intrinsics=k, depth=depth)
