"""Stereo from a flight's photos: adjust all poses (or refine per pair), pick pairs, match, triangulate.

The frame picker, rectification, semi-global matching, filters and back-projection are
``layerpilot.depth``'s; this module puts the image-based poses in front of them - the bundle
adjustment of all photos (``depth.adjust``, the default) or the per-pair refinement
(``depth.refine``, shared with the live depth service) - and says per pair what happened.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np

from layerpilot.depth.picking import FramePicker, PickResult
from layerpilot.depth.stereo import Disparity, StereoMatcher
from layerpilot.geometry import CameraFrame, PointCloud
from layerpilot.depth.adjust import Adjustment, BundleAdjuster
from layerpilot.photos.config import PhotoConfig
from layerpilot.depth.refine import PoseRefiner, Refinement


@dataclass(frozen=True)
class PairResult:
    """One picked pair: ``ref`` is the newer photo (the points are seen from it)."""

    ref: int  # photo indices
    partner: int
    baseline_ratio: float
    refinement: Refinement | None  # None unless refined per pair
    cloud: PointCloud | None  # None when rejected
    coverage: float  # share of the pair's overlap (on the matching grid) that got a depth
    reason: str  # "raw", "adjusted", or the refinement's result

    @property
    def accepted(self) -> bool:
        return self.cloud is not None


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
        self.adjuster = BundleAdjuster(config.adjustment, self.refiner)
        self.adjustment: Adjustment | None = None  # the last run's, with adjusted poses
        self.matcher = StereoMatcher(config.match)
        self._kept: deque[CameraFrame] = deque(maxlen=config.kept)  # live: the flight's recent photos
        self.skipped: Counter[str] = Counter()  # live: why a photo gave no pair

    def picks(self, frames: Sequence[CameraFrame | None]) -> list[tuple[int, PickResult]]:
        """(photo index, pick) for every photo the picker found a partner for (None: a photo left out)."""
        out = []
        for i, frame in enumerate(frames):
            if frame is not None and (pick := self.picker.push(frame)).partner is not None:
                out.append((i, pick))
        return out

    def pair(self, frames: Sequence[CameraFrame], i: int, pick: PickResult) -> PairResult:
        """Refine (if so configured), match and triangulate photo ``i`` with its picked partner."""
        j = int(pick.partner.stamp)
        ref, partner, refinement = frames[i], pick.partner, None
        reason = "raw" if self.config.poses == "raw" else "adjusted"
        if self.config.poses == "refined":
            refinement = self.refiner.refine(ref, partner)
            reason = refinement.reason
            if refinement.ref is None or refinement.partner is None:
                return PairResult(i, j, pick.baseline_ratio, refinement, None, math.nan, reason)
            ref, partner = refinement.ref, refinement.partner
        cloud, disp = self.matcher.cloud(ref, partner)
        return PairResult(i, j, pick.baseline_ratio, refinement, cloud, overlap_coverage(disp, pick.scene_depth),
                          reason)

    def push(self, frame: CameraFrame) -> PairResult | None:
        """Live: the newest photo's pair (None: no partner, the reason counted in ``skipped``).

        The photos nearest the new one (``config.window``, itself included, from the ``config.kept``
        latest) are adjusted together first, as ``run`` adjusts the whole flight: a photo of the
        previous line that overlaps it ties it to the block. Each photo pair is verified once."""
        self._kept.append(frame)
        near = np.linalg.norm([f.pose.position[:2] - frame.pose.position[:2] for f in self._kept], axis=1)
        chosen = sorted(np.argsort(near, kind="stable")[:self.config.window])  # flight order, the new photo last
        window: Sequence[CameraFrame | None] = [self._kept[k] for k in chosen]
        if self.config.poses == "adjusted":
            self.refiner.cache_size = max(self.refiner.cache_size, self.config.kept)
            self.adjuster.link_cache = self.config.kept * self.config.window
            window = self.adjuster.adjust(window).frames
        frames = [None if f is None else replace(f, stamp=float(n)) for n, f in enumerate(window)]  # stamp = index
        if frames[-1] is None:
            self.skipped["not_adjusted"] += 1
            return None
        pick = self.picker.pick(frames[-1], [f for f in frames[:-1] if f is not None])
        if pick.partner is None:
            self.skipped[pick.reason] += 1
            return None
        result = self.pair(frames, len(frames) - 1, pick)
        if result.cloud is None:
            self.skipped[result.reason] += 1
            return result
        return replace(result, cloud=replace(result.cloud, stamp=frame.stamp))

    def run(self, frames: Sequence[CameraFrame], progress: Callable[[int, int], None] | None = None
            ) -> list[PairResult]:
        """Every picked pair's result; ``progress(done, total)`` after each pair.

        With adjusted poses the whole flight is adjusted first; photos the adjustment could not
        tie in (no verified pair) take part in no pair."""
        if self.config.poses == "adjusted":
            self.refiner.cache_size = max(self.refiner.cache_size, len(frames))
            self.adjustment = self.adjuster.adjust(frames)
            frames = self.adjustment.frames
        picks = self.picks(frames)
        results = []
        for k, (i, pick) in enumerate(picks):
            results.append(self.pair(frames, i, pick))
            if progress:
                progress(k + 1, len(picks))
        return results
