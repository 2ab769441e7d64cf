"""Stereo from a sequence of photos: pick pairs, refine their relative pose, match and triangulate.

The frame picker, rectification, semi-global matching, filters and back-projection are
``layerpilot.depth``'s; this module puts the image-based pose refinement between picking
and matching, and says per pair what happened.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np

from layerpilot.depth.picking import FramePicker
from layerpilot.depth.stereo import Disparity, StereoMatcher
from layerpilot.geometry import CameraFrame, PointCloud
from layerpilot.photos.config import PhotoConfig
from layerpilot.photos.refine import PoseRefiner, Refinement


@dataclass(frozen=True)
class PairResult:
    """One picked pair: ``ref`` is the newer frame (the points are seen from it)."""

    ref: int  # frame stamps (photo indices)
    partner: int
    baseline_ratio: float
    refinement: Refinement | None  # None with raw poses
    cloud: PointCloud | None  # None when rejected
    coverage: float  # share of the pair's overlap (on the matching grid) that got a depth

    @property
    def accepted(self) -> bool:
        return self.cloud is not None

    @property
    def reason(self) -> str:
        return "raw" if self.refinement is None else self.refinement.reason


def overlap_coverage(disp: Disparity, scene_depth: float) -> float:
    """Depths found / pixels both rectified images see, the partner's pixel predicted at ``scene_depth``."""
    pair = disp.pair
    h, w = disp.depth.shape
    shift = int(round(pair.f * pair.baseline / scene_depth))
    cols = np.arange(w)
    inside = (cols >= shift)[None, :] & pair.left_valid
    partner = np.zeros_like(inside)
    partner[:, shift:] = pair.right_valid[:, :w - shift] if shift < w else False
    overlap = inside & partner
    n = int(overlap.sum())
    return float((np.isfinite(disp.depth) & overlap).sum() / n) if n else math.nan


class PhotoStereo:
    """Feeds frames in flight order; yields a ``PairResult`` for every frame the picker pairs."""

    def __init__(self, config: PhotoConfig = PhotoConfig()) -> None:
        self.config = config
        self.picker = FramePicker(config.pick)
        self.refiner = PoseRefiner(config.refinement)
        self.matcher = StereoMatcher(config.match)

    def push(self, frame: CameraFrame) -> PairResult | None:
        pick = self.picker.push(frame)
        if pick.partner is None:
            return None
        partner, refinement = pick.partner, None
        if self.config.refine:
            refinement = self.refiner.refine(frame, pick.partner)
            if refinement.ref is None or refinement.partner is None:
                return PairResult(int(frame.stamp), int(partner.stamp), pick.baseline_ratio, refinement, None,
                                  math.nan)
            frame, partner = refinement.ref, refinement.partner
        cloud, disp = self.matcher.cloud(frame, partner)
        return PairResult(int(frame.stamp), int(partner.stamp), pick.baseline_ratio, refinement, cloud,
                          overlap_coverage(disp, pick.scene_depth))

    def run(self, frames: Iterable[CameraFrame]) -> Iterator[PairResult]:
        for frame in frames:
            if (result := self.push(frame)) is not None:
                yield result
