"""Frame picking: which earlier frame makes a usable stereo pair with the newest one.

Rule (also in docs/depth.md): a partner from the recent history is usable when
  0. both have the same image size,
  1. both are sharp: variance of the Laplacian >= ``min_sharpness`` (blurry frames are
     skipped on arrival and never enter the history),
  2. baseline / median scene depth lies in [min_baseline_ratio, max_baseline_ratio],
  3. the relative rotation is at most ``max_rotation_deg``,
  4. each camera's epipole (the other camera's centre projected) lies outside its
     image by ``epipole_margin`` of the image size: the motion is mostly sideways
     to the view, so rectification does not blow up the image around the epipole.
Among the usable partners the one whose ratio is nearest ``target_baseline_ratio``
wins. A frame without a usable partner is skipped; the reason counted is the
failure of the candidate that passed most checks (ties: the most recent one).
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass
from typing import Callable, Iterable

import cv2
import numpy as np

from layerpilot.depth.config import PickConfig
from layerpilot.geometry import CameraFrame

REASONS = ("blurry", "no_history", "size_mismatch", "baseline_short", "baseline_long", "rotation",
           "epipole_inside")


@dataclass(frozen=True)
class PickResult:
    partner: CameraFrame | None
    reason: str  # "ok" or one of REASONS
    scene_depth: float
    baseline_ratio: float = float("nan")


def sharpness(image: np.ndarray) -> float:
    """Variance of the Laplacian of the grey image at <= 320 px width (higher = sharper)."""
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    if grey.shape[1] > 320:
        f = 320 / grey.shape[1]
        grey = cv2.resize(grey, None, fx=f, fy=f, interpolation=cv2.INTER_AREA)
    return float(cv2.Laplacian(grey, cv2.CV_32F).var())


def altitude_scene_depth(frame: CameraFrame, ground_z: float, max_depth: float) -> float:
    """Median scene depth guessed from height over flat ground along the optical axis."""
    down = -frame.optical_axis[2]  # cosine between optical axis and straight down
    height = frame.pose.position[2] - ground_z
    if down <= 1e-3 or height <= 0:
        return max_depth
    return float(np.clip(height / down, 1.0, max_depth))


def rotation_angle_deg(a: CameraFrame, b: CameraFrame) -> float:
    r = a.pose.rotation.T @ b.pose.rotation
    return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0))))


def epipole_outside(cam: CameraFrame, other: CameraFrame, margin: float) -> bool:
    """True when ``other``'s centre projects outside ``cam``'s image (or to infinity)."""
    c = cam.pose.to_local(other.pose.position[None])[0]
    if abs(c[2]) <= 1e-9 * np.linalg.norm(c):
        return True
    k = cam.intrinsics
    u, v = k.fx * c[0] / c[2] + k.cx, k.fy * c[1] / c[2] + k.cy
    w, h = cam.size
    return not (-margin * w <= u <= (1 + margin) * w and -margin * h <= v <= (1 + margin) * h)


class FramePicker:
    """Keeps a short frame history and picks the stereo partner of each new frame."""

    def __init__(self, config: PickConfig = PickConfig(),
                 scene_depth: Callable[[CameraFrame], float] | None = None) -> None:
        self.config = config
        self._scene_depth = scene_depth
        self._history: deque[CameraFrame] = deque(maxlen=config.history)
        self.skipped: Counter[str] = Counter()
        self.pairs = 0

    def scene_depth(self, frame: CameraFrame) -> float:
        if self._scene_depth is not None:
            return float(self._scene_depth(frame))
        return altitude_scene_depth(frame, self.config.ground_z, self.config.max_depth)

    def push(self, frame: CameraFrame) -> PickResult:
        """Add ``frame`` and return its partner from the history (or the reason there is none)."""
        result = self.pick(frame, self._history)
        if result.reason != "blurry":
            self._history.append(frame)
        return result

    def pick(self, frame: CameraFrame, candidates: Iterable[CameraFrame]) -> PickResult:
        """``frame``'s partner among ``candidates`` (oldest first; ties go to the most recent), counted."""
        cfg = self.config
        depth = self.scene_depth(frame)
        if sharpness(frame.image) < cfg.min_sharpness:
            return self._skip("blurry", depth)
        best: tuple[float, CameraFrame, float] | None = None
        failure, failure_stage = "no_history", -1
        for cand in reversed(list(candidates)):
            stage, reason, ratio = self._check(frame, cand, depth)
            if reason == "ok":
                score = abs(ratio - cfg.target_baseline_ratio)
                if best is None or score < best[0]:
                    best = (score, cand, ratio)
            elif stage > failure_stage:
                failure, failure_stage = reason, stage
        if best is None:
            return self._skip(failure, depth)
        self.pairs += 1
        return PickResult(best[1], "ok", depth, best[2])

    def _check(self, frame: CameraFrame, cand: CameraFrame, depth: float) -> tuple[int, str, float]:
        cfg = self.config
        ratio = float(np.linalg.norm(frame.pose.position - cand.pose.position)) / depth
        if cand.size != frame.size:
            return 0, "size_mismatch", ratio
        if ratio < cfg.min_baseline_ratio:
            return 1, "baseline_short", ratio
        if ratio > cfg.max_baseline_ratio:
            return 1, "baseline_long", ratio
        if rotation_angle_deg(frame, cand) > cfg.max_rotation_deg:
            return 2, "rotation", ratio
        if not (epipole_outside(frame, cand, cfg.epipole_margin) and epipole_outside(cand, frame, cfg.epipole_margin)):
            return 3, "epipole_inside", ratio
        return 4, "ok", ratio

    def _skip(self, reason: str, depth: float) -> PickResult:
        self.skipped[reason] += 1
        return PickResult(None, reason, depth)
