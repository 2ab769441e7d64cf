"""Relative pose of two photos from their images, scaled by GNSS.

GNSS is metres off and attitude about a degree: too coarse for two-view stereo (one degree
moves a point 0.7 m at 40 m). The images fix the relative rotation and the direction of the
baseline to a fraction of that: SIFT features, Lowe's ratio test, the essential matrix with
RANSAC and ``cv2.recoverPose``. The length of the baseline (the scale, which images cannot
give) comes from GNSS. The partner's pose is then the reference camera's pose composed with
the image-derived relative pose: the pair is self-consistent, the reference camera keeps its
GNSS position and attitude. A pair is rejected when the images and GNSS/attitude disagree by
more than ``max_rotation_deg`` in rotation or ``max_direction_deg`` in baseline direction, or
when too few matches survive RANSAC (fewer than ``min_inliers`` or ``min_inlier_ratio`` of
the matches: on the forest of the first flight line a quarter of the matches fit an essential
matrix whose depths were wrong everywhere).

One disagreement is corrected instead (``flip_heading``): when the images put the partner on
the opposite side of where GNSS puts it, the recorded heading is 180 degrees off (on the
Brighton Beach flight's second line the XMP yaw points against the direction of flight while
the images and GNSS agree with each other); the reference camera is then turned half a turn
about the vertical and the pair is reported as ``ok_heading_flipped``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from layerpilot.geometry import CameraFrame, Pose
from layerpilot.photos.config import RefineConfig


@dataclass(frozen=True)
class Refinement:
    """What the images said about a pair; ``ref`` and ``partner`` are the corrected frames, None if rejected."""

    ref: CameraFrame | None
    partner: CameraFrame | None
    matches: int
    inliers: int
    rotation_correction_deg: float  # angle between the GNSS/attitude and the image relative rotation
    direction_correction_deg: float  # angle between the two baseline directions
    reason: str  # "ok" or why the pair was rejected


HALF_TURN = np.diag([-1.0, -1.0, 1.0])  # 180 degrees about the vertical (map z)


def angle_deg(R: np.ndarray) -> float:
    """Rotation angle of a 3x3 rotation matrix, degrees."""
    return math.degrees(math.acos(float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def _grey(frame: CameraFrame) -> np.ndarray:
    return cv2.cvtColor(frame.image, cv2.COLOR_RGB2GRAY)


class PoseRefiner:
    """Refines the partner's pose of stereo pairs; keeps the features of recent frames."""

    def __init__(self, config: RefineConfig = RefineConfig()) -> None:
        self.config = config
        self._sift = cv2.SIFT_create(config.features)
        self._matcher = cv2.BFMatcher(cv2.NORM_L2)
        # id(image) -> (image, points, descriptors); holding the image keeps its id from being reused
        self._cache: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.cache_size = 8  # frames; the bundle adjustment raises it to the flight's photo count

    def features(self, frame: CameraFrame) -> tuple[np.ndarray, np.ndarray]:
        """Keypoint pixels (N, 2) and SIFT descriptors of a frame, cached by its image."""
        key = id(frame.image)
        if key not in self._cache:
            if len(self._cache) > self.cache_size:
                self._cache.pop(next(iter(self._cache)))
            kp, desc = self._sift.detectAndCompute(_grey(frame), None)
            self._cache[key] = (frame.image, np.float32([k.pt for k in kp]).reshape(-1, 2),
                                desc if desc is not None else np.zeros((0, 128), np.float32))
        return self._cache[key][1:]

    def matches(self, ref: CameraFrame, other: CameraFrame) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) of ratio-test matches in ``ref`` and ``other``."""
        (pa, da), (pb, db) = self.features(ref), self.features(other)
        if len(da) < 2 or len(db) < 2:
            return np.zeros((0, 2), np.float32), np.zeros((0, 2), np.float32)
        pairs = [m for m, n in (p for p in self._matcher.knnMatch(da, db, k=2) if len(p) == 2)
                 if m.distance < self.config.ratio * n.distance]
        return pa[[m.queryIdx for m in pairs]], pb[[m.trainIdx for m in pairs]]

    def refine(self, ref: CameraFrame, other: CameraFrame) -> Refinement:
        """The partner ``other`` with the relative pose the images give, or the reason not."""
        c = self.config
        pa, pb = self.matches(ref, other)
        if len(pa) < c.min_inliers:
            return Refinement(None, None, len(pa), 0, math.nan, math.nan, "too_few_matches")
        if ref.intrinsics != other.intrinsics:
            raise ValueError("other: intrinsics differ from ref's; refinement assumes one camera")
        E, mask = cv2.findEssentialMat(pa, pb, ref.K, cv2.RANSAC, 0.999, c.ransac_px)
        if E is None or E.shape != (3, 3):
            return Refinement(None, None, len(pa), 0, math.nan, math.nan, "no_essential_matrix")
        inliers, R, t, _ = cv2.recoverPose(E, pa, pb, ref.K, mask=mask)
        # x_other = R x_ref + t in camera coordinates; the same from GNSS and attitude:
        R_gnss = other.pose.rotation.T @ ref.pose.rotation
        t_gnss = other.pose.rotation.T @ (ref.pose.position - other.pose.position)
        baseline = float(np.linalg.norm(t_gnss))
        t = t.ravel()
        rotation = angle_deg(R_gnss.T @ R)
        direction = math.degrees(math.acos(float(np.clip(t @ t_gnss / baseline, -1.0, 1.0))))
        flipped = direction > 180.0 - c.max_direction_deg and c.flip_heading
        if flipped:  # the images see the partner behind where GNSS puts it: the heading is off by 180 degrees
            ref = replace(ref, pose=Pose.from_rotation(HALF_TURN @ ref.pose.rotation, ref.pose.position))
            direction = 180.0 - direction
        reason = ("too_few_inliers" if inliers < max(c.min_inliers, c.min_inlier_ratio * len(pa)) else
                  "rotation_disagrees" if rotation > c.max_rotation_deg else
                  "direction_disagrees" if direction > c.max_direction_deg else "ok")
        if reason != "ok":
            return Refinement(None, None, len(pa), int(inliers), rotation, direction, reason)
        R_other = ref.pose.rotation @ R.T
        centre = ref.pose.position - R_other @ (t * baseline)
        return Refinement(ref, replace(other, pose=Pose.from_rotation(R_other, centre)), len(pa), int(inliers),
                          rotation, direction, "ok_heading_flipped" if flipped else "ok")
