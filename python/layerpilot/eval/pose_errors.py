"""Pose error over a mission: estimated camera poses against the true ones, up to the map's offset.

Position is compared after removing the same translation the map is scored with
(``eval.alignment``: estimated minus true), attitude as the angle of the rotation between
the two orientations. Median and 90th percentile, as trajectory benchmarks report them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from layerpilot.geometry import Pose

StampedPose = tuple[float, Pose]  # (mission-clock stamp in seconds, camera -> map pose)
MAX_STAMP_GAP = 0.25  # seconds; an estimate pairs with the true pose nearest in time, at most this far


@dataclass(frozen=True)
class PoseErrors:
    position_median: float  # metres, after removing the offset
    position_p90: float
    attitude_median_deg: float
    attitude_p90_deg: float
    poses: int

    def as_dict(self, prefix: str) -> dict[str, float]:
        """Keys ``<prefix>_position_median`` etc.: a report holds the raw and the refined trajectory."""
        return {f"{prefix}_{k}": float(v) for k, v in self.__dict__.items()}


def _rotations(poses: Sequence[Pose]) -> Rotation:
    q = np.array([p.orientation for p in poses])  # (w, x, y, z)
    return Rotation.from_quat(q[:, [1, 2, 3, 0]])


def _paired(truth: Sequence[StampedPose], estimate: Sequence[StampedPose], max_gap: float
            ) -> tuple[list[Pose], list[Pose]]:
    """Each estimated pose with the true pose nearest to its stamp (within ``max_gap``), in estimate order."""
    if not truth or not estimate:
        raise ValueError(f"truth, estimate: need at least one pose each, got {len(truth)} and {len(estimate)}")
    true_t = np.array([t for t, _ in truth], np.float64)
    order = np.argsort(true_t, kind="stable")
    true_t = true_t[order]
    est_t = np.array([t for t, _ in estimate], np.float64)
    right = np.minimum(np.searchsorted(true_t, est_t), len(true_t) - 1)
    left = np.maximum(right - 1, 0)
    nearest = np.where(np.abs(true_t[left] - est_t) <= np.abs(true_t[right] - est_t), left, right)
    gap = np.abs(true_t[nearest] - est_t)
    if np.any(gap > max_gap):
        i = int(np.argmax(gap))
        raise ValueError(f"estimate: the pose at t = {est_t[i]:.3f} s has no true pose within {max_gap} s")
    return [truth[int(order[i])][1] for i in nearest], [p for _, p in estimate]


def common_offset(truth: Sequence[StampedPose], estimate: Sequence[StampedPose],
                  max_gap: float = MAX_STAMP_GAP) -> np.ndarray:
    """The translation the estimated positions share (estimated minus true, metres): the per-axis median
    over the paired poses, what a GNSS offset leaves behind in a trajectory."""
    true_poses, est_poses = _paired(truth, estimate, max_gap)
    return np.median(np.array([e.position - t.position for t, e in zip(true_poses, est_poses)]), axis=0)


def pose_errors(truth: Sequence[StampedPose], estimate: Sequence[StampedPose], offset=(0.0, 0.0, 0.0),
                max_gap: float = MAX_STAMP_GAP) -> PoseErrors:
    """Median and p90 of position (metres) and attitude (degrees) errors of ``estimate`` against ``truth``.

    Each estimated pose is paired with the true pose nearest to its stamp (within ``max_gap``);
    ``offset`` (estimated minus true, metres) is subtracted from every estimated position first.
    """
    shift = np.asarray(offset, np.float64)
    if shift.shape != (3,) or not np.all(np.isfinite(shift)):
        raise ValueError(f"offset: expected 3 finite metres, got {offset!r}")
    true_poses, est_poses = _paired(truth, estimate, max_gap)
    position = np.linalg.norm(np.array([p.position for p in est_poses]) - shift
                              - np.array([p.position for p in true_poses]), axis=1)
    attitude = np.degrees((_rotations(true_poses).inv() * _rotations(est_poses)).magnitude())
    return PoseErrors(float(np.median(position)), float(np.percentile(position, 90)),
                      float(np.median(attitude)), float(np.percentile(attitude, 90)), len(est_poses))
