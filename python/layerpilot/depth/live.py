"""Live pose refinement: every stereo pair of the depth service placed from its images, the recent
trajectory adjusted as one, the camera clock's offset learnt - before any point reaches the map.

Per pair (``refine``): the frames' priors are the reported poses (re-read from the telemetry
stream at the camera stamp plus the learnt clock offset, once it is known); the images give the
relative rotation and baseline direction (``depth.refine``: KLT tracks of the partner's points,
essential matrix, polish); a pair whose images disagree with the priors, or whose transferred
scale disagrees with the GNSS baseline, is rejected with the reason. Accepted pairs become edges
of the sliding window (``depth.window``), which re-estimates the recent keyframes; the pair is
then matched with the reference camera at its window estimate and the partner placed exactly
where the images put it, at the window's baseline length.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field, replace

import numpy as np

from layerpilot.config import check_range
from layerpilot.depth.clock import PoseHistory, TimeOffset
from layerpilot.depth.config import RefineConfig
from layerpilot.depth.refine import PoseRefiner, Relative, disagreement, place, triangulate
from layerpilot.depth.window import Edge, Keyframe, SlidingWindow, WindowConfig
from layerpilot.geometry import CameraFrame, Pose

REJECTIONS = ("too_few_matches", "no_essential_matrix", "too_few_inliers", "rotation_disagrees",  # why a pair gave no cloud
              "direction_disagrees", "scale_disagrees", "adjustment_failed")


@dataclass(frozen=True)
class LiveConfig:
    """Live refinement settings; the defaults are the measured ones of docs/depth.md."""

    pair: RefineConfig = field(default_factory=lambda: RefineConfig(
        detector="klt", features=400, min_inliers=40, min_inlier_ratio=0.5, max_rotation_deg=5.0,
        max_direction_deg=25.0, flip_heading=False, polish=True))
    window: WindowConfig = field(default_factory=WindowConfig)
    feature_width: int = 320  # px: frames are tracked at this width (or their own, if narrower)
    max_offset: float = 0.5  # s: the camera clock's offset is searched within this each way
    min_offset_pairs: int = 5  # pairs over which the camera turned before the offset is used
    min_scale_points: int = 20  # points seen again to carry the scale over from the partner's pair
    max_scale_ratio: float = 1.5  # transferred baseline / GNSS baseline beyond this (or 1 / this): rejected
    gimbal: bool = True  # the camera keeps only the body's heading (the telemetry's roll and pitch do not turn it)

    def __post_init__(self) -> None:
        check_range("max_offset", self.max_offset, 0.0, 10.0)
        check_range("feature_width", self.feature_width, 64)
        check_range("min_offset_pairs", self.min_offset_pairs, 1)
        check_range("min_scale_points", self.min_scale_points, 5)
        check_range("max_scale_ratio", self.max_scale_ratio, 1.0)


class LiveRefiner:
    """Refines the pairs of one camera; fed the vehicle's telemetry poses (body -> map) when there are any."""

    def __init__(self, config: LiveConfig = LiveConfig()) -> None:
        self.config = config
        self.pairs: PoseRefiner | None = None  # made for the first frame's width
        self.window = SlidingWindow(config.window)
        self.offset = TimeOffset(config.max_offset, min_pairs=config.min_offset_pairs)
        self.body = PoseHistory()
        self.cameras = PoseHistory()
        self.mount: Pose | None = None  # camera -> (heading-only) body, learnt from a frame the telemetry covers
        self._unplaced: deque[tuple[float, Pose]] = deque(maxlen=16)  # frames' (stamp, reported pose) until then
        self.refined = 0
        self.rejected: Counter[str] = Counter()
        self._trajectory: dict[float, Pose] = {}

    def push_pose(self, stamp: float, pose: Pose) -> None:
        """One telemetry pose (body FLU -> map) on the telemetry clock."""
        self.body.add(stamp, pose)
        if self.mount is not None:
            self.cameras.add(stamp, self._camera(pose))

    def _camera(self, body: Pose) -> Pose:
        if self.config.gimbal:
            body = Pose.from_euler(0.0, 0.0, body.yaw, body.position)
        return body @ self.mount

    def _learn_mount(self, frame: CameraFrame) -> None:
        """The camera's mount from a frame whose reported pose is the telemetry's at its stamp (the
        telemetry may not have reached a frame's stamp yet: the newest frames wait for it)."""
        if self.mount is not None:
            return
        self._unplaced.append((frame.stamp, frame.pose))
        for stamp, pose in self._unplaced:
            if (body := self.body.at(stamp)) is not None:
                if self.config.gimbal:
                    body = Pose.from_euler(0.0, 0.0, body.yaw, body.position)
                self.mount = body.inverse() @ pose
                for t, p in zip(self.body.stamps, self.body.poses):
                    self.cameras.add(t, self._camera(p))
                self._unplaced.clear()
                return

    @property
    def time_offset(self) -> float | None:
        """Seconds to add to a frame's stamp to read the telemetry at its exposure; None until known."""
        return self.offset.estimate

    def prior(self, frame: CameraFrame) -> Pose:
        """The frame's reported pose, re-read from the telemetry at stamp + offset once the offset is known
        (a little past the newest telemetry pose by extrapolation, so that the two frames of a pair are
        never placed on different clocks)."""
        pose = self._on_telemetry_clock(frame.stamp)
        return frame.pose if pose is None else pose

    def _on_telemetry_clock(self, stamp: float) -> Pose | None:
        """The camera's telemetry pose at camera-clock ``stamp`` + the offset; None while either is unknown."""
        if (dt := self.time_offset) is None:
            return None
        return self.cameras.at(stamp + dt, ahead=self.config.max_offset)

    def _reread_priors(self) -> None:
        """Every keyframe's prior re-read from the telemetry at the current offset: the frames placed
        before the offset was known (or before the telemetry reached them) join the same clock."""
        for kf in self.window.frames.values():
            if (pose := self._on_telemetry_clock(kf.stamp)) is not None:
                kf.prior = pose

    def refine(self, frame: CameraFrame, partner: CameraFrame) -> tuple[CameraFrame, CameraFrame] | None:
        """The pair with refined poses (``frame`` is the newer, its points are published), or None
        (the reason counted in ``rejected``)."""
        c = self.config
        self._learn_mount(frame)
        prior_f = self.prior(frame)
        other = self.window.frames.get(partner.stamp)
        prior_o = other.prior if other is not None else self.prior(partner)
        seeds = other.points_px if other is not None else None
        if self.pairs is None:
            self.pairs = PoseRefiner(replace(c.pair, scale=min(1.0, c.feature_width / frame.size[0])))
        rel, reason, _, _ = self.pairs.relative(frame, partner, seeds)
        if rel is not None:
            rotation, direction = disagreement(prior_f, prior_o, rel)
            reason = ("rotation_disagrees" if rotation > c.pair.max_rotation_deg else
                      "direction_disagrees" if direction > c.pair.max_direction_deg else "ok")
        if rel is None or reason != "ok":
            self.rejected[reason] += 1
            return None
        self.offset.add(frame.stamp, partner.stamp, rel.R)
        if self.mount is not None:
            self.offset.update(self.cameras)
        self._reread_priors()
        prior_f = self.prior(frame)
        prior_o = other.prior if other is not None else self.prior(partner)
        gnss = float(np.linalg.norm(prior_f.position - prior_o.position))
        points = triangulate(frame.K, rel)  # unit baseline, the new frame's axes
        length = self._transfer(other, rel, points) if other is not None else math.nan
        if math.isfinite(length) and not 1 / c.max_scale_ratio <= length / max(gnss, 1e-9) <= c.max_scale_ratio:
            self.rejected["scale_disagrees"] += 1
            return None
        other = self.window.keyframe(partner.stamp, prior_o)
        new = self.window.keyframe(frame.stamp, prior_f)
        new.pose = _ref_from_other(other.pose, rel, length if math.isfinite(length) else gnss)
        if not self.window.add(Edge(frame.stamp, partner.stamp, rel, length)):
            self.rejected["adjustment_failed"] += 1
            return None
        baseline = float(np.linalg.norm(new.pose.position - other.pose.position))
        ok = np.isfinite(points).all(1) & (points[:, 2] > 0)
        new.points_px, new.points = rel.ref_px[ok], points[ok] * baseline
        for kf in self.window.frames.values():
            self._trajectory[kf.stamp] = kf.pose
        self.refined += 1
        return replace(frame, pose=new.pose), replace(partner, pose=place(new.pose, rel, baseline))

    def _transfer(self, other: Keyframe, rel: Relative, points: np.ndarray) -> float:
        """The baseline length that puts the partner's earlier points, seen again, at their depths; NaN if too few."""
        seen = rel.seeds >= 0
        if seen.sum() < self.config.min_scale_points:
            return math.nan
        X_other = points[seen] @ rel.R.T + rel.t  # unit baseline, the partner's axes
        z_metric = other.points[rel.seeds[seen], 2]
        ok = (X_other[:, 2] > 0) & (z_metric > 0)
        if ok.sum() < self.config.min_scale_points:
            return math.nan
        return float(np.median(z_metric[ok] / X_other[ok, 2]))

    def trajectory(self) -> list[tuple[float, Pose]]:
        """The refined camera poses so far (stamp on the camera clock, camera -> map), oldest first."""
        return sorted(self._trajectory.items())

    def stats(self) -> dict[str, float]:
        """Pairs refined, rejected per reason, and the clock offset once known (with the pairs it rests on)."""
        dt = self.time_offset
        return {"refined": self.refined, **{f"rejected_{k}": self.rejected[k] for k in REJECTIONS},
                **({"time_offset_s": round(dt, 4)} if dt is not None else {}), "time_offset_pairs": self.offset.pairs}


def _ref_from_other(other: Pose, rel: Relative, baseline: float) -> Pose:
    """The reference camera's pose from the other's and the images' relative pose (x_other = R x_ref + t)."""
    R_ref = other.rotation @ rel.R
    return Pose.from_rotation(R_ref, other.position + other.rotation @ rel.t * baseline)
