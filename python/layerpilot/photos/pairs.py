"""Stereo from a flight's photos: pick pairs, refine their relative pose, match, triangulate.

The frame picker, rectification, semi-global matching, filters and back-projection are
``layerpilot.depth``'s; this module puts the image-based pose refinement (``photos.refine``)
between picking and matching, and says per pair what happened.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from layerpilot.depth.picking import FramePicker, PickResult
from layerpilot.depth.stereo import Disparity, StereoMatcher
from layerpilot.geometry import CameraFrame, PointCloud
from layerpilot.photos.config import PhotoConfig
from layerpilot.photos.refine import PoseRefiner, Refinement


@dataclass(frozen=True)
class PairResult:
    """One picked pair: ``ref`` is the newer photo (the points are seen from it)."""

    ref: int  # photo indices
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
    """Stereo pairs of a flight, in flight order (frame ``stamp`` = photo index)."""

    def __init__(self, config: PhotoConfig = PhotoConfig()) -> None:
        self.config = config
        self.picker = FramePicker(config.pick)
        self.refiner = PoseRefiner(config.refinement)
        self.matcher = StereoMatcher(config.match)

    def picks(self, frames: Sequence[CameraFrame]) -> list[tuple[int, PickResult]]:
        """(photo index, pick) for every photo the picker found a partner for."""
        out = []
        for i, frame in enumerate(frames):
            if (pick := self.picker.push(frame)).partner is not None:
                out.append((i, pick))
        return out

    def pair(self, frames: Sequence[CameraFrame], i: int, pick: PickResult) -> PairResult:
        """Refine (unless configured off), match and triangulate photo ``i`` with its picked partner."""
        j = int(pick.partner.stamp)
        ref, partner, refinement = frames[i], pick.partner, None
        if self.config.refine:
            refinement = self.refiner.refine(ref, partner)
            if refinement.ref is None or refinement.partner is None:
                return PairResult(i, j, pick.baseline_ratio, refinement, None, math.nan)
            ref, partner = refinement.ref, refinement.partner
        cloud, disp = self.matcher.cloud(ref, partner)
        return PairResult(i, j, pick.baseline_ratio, refinement, cloud, overlap_coverage(disp, pick.scene_depth))

    def run(self, frames: Sequence[CameraFrame], progress: Callable[[int, int], None] | None = None
            ) -> list[PairResult]:
        """Every picked pair's result; ``progress(done, total)`` after each pair."""
        picks = self.picks(frames)
        results = []
        for k, (i, pick) in enumerate(picks):
            results.append(self.pair(frames, i, pick))
            if progress:
                progress(k + 1, len(picks))
        return results
