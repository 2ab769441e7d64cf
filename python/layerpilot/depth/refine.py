"""Relative pose of two frames from their images, scaled by GNSS: the photo pipeline's pairs and
the live depth service's (``depth.live``) share it.

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
from layerpilot.depth.config import RefineConfig


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
POLISH_POINTS = 200  # inliers the polish uses: more cost time and moved the pose by less than its error


def angle_deg(R: np.ndarray) -> float:
    """Rotation angle of a 3x3 rotation matrix, degrees."""
    return math.degrees(math.acos(float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def _grey(frame: CameraFrame, scale: float = 1.0) -> np.ndarray:
    grey = cv2.cvtColor(frame.image, cv2.COLOR_RGB2GRAY)
    return grey if scale == 1.0 else cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


@dataclass(frozen=True)
class Relative:
    """The relative pose the images give, ``x_other = R x_ref + t`` in camera coordinates (``|t| = 1``),
    with the pixels of its inlier matches in both images."""

    R: np.ndarray
    t: np.ndarray
    ref_px: np.ndarray  # (N, 2) float32, full-resolution pixels
    other_px: np.ndarray
    seeds: np.ndarray  # (N,) int: index into the ``seeds`` the match was tracked from, -1 for a fresh corner
    matches: int  # before RANSAC


class PoseRefiner:
    """Relative poses of frame pairs from their images; keeps the features of recent frames.

    Two front ends: SIFT keypoints matched by descriptor (wide baselines, photos) or KLT: the
    partner's corners tracked into the newer frame by pyramidal optical flow, kept when the
    backward track returns within half a pixel (a live camera's close frames, a tenth of the cost)."""

    def __init__(self, config: RefineConfig = RefineConfig()) -> None:
        self.config = config
        self._sift = cv2.SIFT_create(config.features)
        self._matcher = cv2.BFMatcher(cv2.NORM_L2)
        # id(image) -> (image, points, descriptors); holding the image keeps its id from being reused
        self._cache: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.cache_size = 8  # frames; the bundle adjustment raises it to the flight's photo count

    def _cached(self, frame: CameraFrame, make) -> tuple:
        key = id(frame.image)
        if key not in self._cache:
            if len(self._cache) > self.cache_size:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = (frame.image, *make())
        return self._cache[key][1:]

    def features(self, frame: CameraFrame) -> tuple[np.ndarray, np.ndarray]:
        """Keypoint pixels (N, 2) and SIFT descriptors of a frame, cached by its image."""
        def make():
            kp, desc = self._sift.detectAndCompute(_grey(frame, self.config.scale), None)
            return (_full(np.float32([k.pt for k in kp]).reshape(-1, 2), self.config.scale),
                    desc if desc is not None else np.zeros((0, 128), np.float32))
        return self._cached(frame, make)

    def matches(self, ref: CameraFrame, other: CameraFrame, seeds: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) of matches in ``ref`` and ``other`` and each one's seed index (-1: none).

        ``seeds`` (KLT only): pixels of ``other`` to track first, before fresh corners."""
        if self.config.detector == "klt":
            return self._tracks(ref, other, seeds)
        (pa, da), (pb, db) = self.features(ref), self.features(other)
        if len(da) < 2 or len(db) < 2:
            return np.zeros((0, 2), np.float32), np.zeros((0, 2), np.float32), np.zeros(0, int)
        pairs = [m for m, n in (p for p in self._matcher.knnMatch(da, db, k=2) if len(p) == 2)
                 if m.distance < self.config.ratio * n.distance]
        return pa[[m.queryIdx for m in pairs]], pb[[m.trainIdx for m in pairs]], np.full(len(pairs), -1)

    def _tracks(self, ref: CameraFrame, other: CameraFrame, seeds: np.ndarray | None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        c = self.config
        g_ref = self._cached(ref, lambda: (_grey(ref, c.scale),))[0]
        g_other = self._cached(other, lambda: (_grey(other, c.scale),))[0]
        seeds = np.zeros((0, 2), np.float32) if seeds is None else np.asarray(seeds, np.float32).reshape(-1, 2)
        fresh = cv2.goodFeaturesToTrack(g_other, max(c.features - len(seeds), 1), 0.01, 8, blockSize=7)
        fresh = np.zeros((0, 2), np.float32) if fresh is None else fresh.reshape(-1, 2)
        start = np.vstack([(seeds + 0.5) * c.scale - 0.5, fresh]).astype(np.float32)
        if len(start) == 0:
            return np.zeros((0, 2), np.float32), np.zeros((0, 2), np.float32), np.zeros(0, int)
        lk = dict(winSize=(15, 15), maxLevel=3, criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.03))
        fwd, st, _ = cv2.calcOpticalFlowPyrLK(g_other, g_ref, start, None, **lk)
        ok = st.ravel() == 1
        if ok.any():  # back only what the forward pass found (LK tracks each point on its own; a lost point costs most)
            back, st2, _ = cv2.calcOpticalFlowPyrLK(g_ref, g_other, fwd[ok], None, **lk)
            ok[ok] = (st2.ravel() == 1) & (np.linalg.norm(back - start[ok], axis=1) < 0.5)
        index = np.where(np.arange(len(start)) < len(seeds), np.arange(len(start)), -1)
        return _full(fwd[ok], c.scale), _full(start[ok], c.scale), index[ok]

    def relative(self, ref: CameraFrame, other: CameraFrame, seeds: np.ndarray | None = None
                 ) -> tuple[Relative | None, str, int, int]:
        """The images' relative pose (None and the reason when they cannot say), the matches and the RANSAC inliers."""
        c = self.config
        if ref.intrinsics != other.intrinsics:
            raise ValueError("other: intrinsics differ from ref's; refinement assumes one camera")
        pa, pb, idx = self.matches(ref, other, seeds)
        if len(pa) < c.min_inliers:
            return None, "too_few_matches", len(pa), 0
        px = c.ransac_px / c.scale
        if (found := essential_pose(pa, pb, ref.K, px)) is None:
            return None, "no_essential_matrix", len(pa), 0
        inliers, R, t, mask = found
        if inliers < max(c.min_inliers, c.min_inlier_ratio * len(pa)):
            return None, "too_few_inliers", len(pa), int(inliers)
        keep = mask.ravel() > 0
        pa, pb, idx, t = pa[keep], pb[keep], idx[keep], t.ravel()
        if c.polish:
            try:
                R, t = polish(ref.K, pa, pb, R, t, px)
            except np.linalg.LinAlgError:  # degenerate inliers (all on one line): RANSAC's pose stands
                pass
        return Relative(R, t, pa, pb, idx, len(keep)), "ok", len(keep), int(inliers)

    def refine(self, ref: CameraFrame, other: CameraFrame) -> Refinement:
        """The partner ``other`` with the relative pose the images give, or the reason not.

        The reference keeps its pose; the baseline's length is the GNSS one."""
        c = self.config
        rel, reason, matches, inliers = self.relative(ref, other)
        if rel is None:
            return Refinement(None, None, matches, inliers, math.nan, math.nan, reason)
        rotation, direction = disagreement(ref.pose, other.pose, rel)
        flipped = direction > 180.0 - c.max_direction_deg and c.flip_heading
        if flipped:  # the images see the partner behind where GNSS puts it: the heading is off by 180 degrees
            ref = replace(ref, pose=Pose.from_rotation(HALF_TURN @ ref.pose.rotation, ref.pose.position))
            direction = 180.0 - direction
        reason = ("rotation_disagrees" if rotation > c.max_rotation_deg else
                  "direction_disagrees" if direction > c.max_direction_deg else "ok")
        if reason != "ok":
            return Refinement(None, None, rel.matches, inliers, rotation, direction, reason)
        baseline = float(np.linalg.norm(ref.pose.position - other.pose.position))
        return Refinement(ref, replace(other, pose=place(ref.pose, rel, baseline)), rel.matches, inliers,
                          rotation, direction, "ok_heading_flipped" if flipped else "ok")


def disagreement(ref: Pose, other: Pose, rel: Relative) -> tuple[float, float]:
    """Degrees between the priors' and the images' relative rotation, and between their baseline directions."""
    R_prior = other.rotation.T @ ref.rotation  # x_other = R x_ref + t from the priors
    t_prior = other.rotation.T @ (ref.position - other.position)
    rotation = angle_deg(R_prior.T @ rel.R)
    norm = float(np.linalg.norm(t_prior))
    direction = math.degrees(math.acos(float(np.clip(rel.t @ t_prior / norm, -1.0, 1.0)))) if norm > 0 else 180.0
    return rotation, direction


def place(ref: Pose, rel: Relative, baseline: float) -> Pose:
    """The other camera's pose: ``ref`` composed with the images' relative pose, ``baseline`` metres away."""
    R_other = ref.rotation @ rel.R.T
    return Pose.from_rotation(R_other, ref.position - R_other @ (rel.t * baseline))


def _full(px: np.ndarray, scale: float) -> np.ndarray:
    """Working-scale pixels -> full-resolution pixels (pixel centres keep their place)."""
    return px if scale == 1.0 else ((px + 0.5) / scale - 0.5).astype(np.float32)


def polish(K: np.ndarray, pa: np.ndarray, pb: np.ndarray, R: np.ndarray, t: np.ndarray, px: float,
           iterations: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) minimising the robust (Huber at ``px``) Sampson error of the inliers (at most
    ``POLISH_POINTS``, evenly taken) by reweighted Gauss-Newton: RANSAC's minimal-sample pose is
    several times less accurate than what all the matches say."""
    if len(pa) > POLISH_POINTS:
        keep = np.linspace(0, len(pa) - 1, POLISH_POINTS).astype(int)
        pa, pb = pa[keep], pb[keep]
    Ki = np.linalg.inv(K)
    xa = np.column_stack([pa, np.ones(len(pa))]) @ Ki.T
    xb = np.column_stack([pb, np.ones(len(pb))]) @ Ki.T
    t = t / np.linalg.norm(t)
    h = 1e-6
    probes = np.vstack([np.zeros(5), h * np.eye(5)])  # the pose and a step along each of its 5 freedoms
    turns = rotation_matrices(probes[:, :3])  # the probes' rotations do not depend on the pose
    for _ in range(iterations):
        basis = _tangent(t)
        tt = t + probes[:, 3:] @ basis
        res = _sampson(xa, xb, turns @ R, tt / np.sqrt((tt * tt).sum(1))[:, None]) * K[0, 0]  # (6, N)
        r0, J = res[0], (res[1:] - res[0]) / h  # J: (5, N)
        w = np.minimum(1.0, px / np.maximum(np.abs(r0), 1e-12))  # Huber's weights
        step = -np.linalg.solve((J * w) @ J.T + 1e-12 * np.eye(5), (J * w) @ r0)
        R = rotation_matrices(step[None, :3])[0] @ R
        t = t + step[3:] @ basis
        t = t / math.sqrt(t @ t)
        if np.abs(step).max() < 1e-7:
            break
    return R, t


def _tangent(t: np.ndarray) -> np.ndarray:
    """Two unit vectors (2, 3) across the unit vector ``t``, the second ``t x`` the first."""
    a = (1.0, 0.0, 0.0) if abs(t[0]) < 0.9 else (0.0, 1.0, 0.0)
    u = np.array([t[1] * a[2] - t[2] * a[1], t[2] * a[0] - t[0] * a[2], t[0] * a[1] - t[1] * a[0]])
    u /= math.sqrt(u @ u)
    return np.array([u, [t[1] * u[2] - t[2] * u[1], t[2] * u[0] - t[0] * u[2], t[0] * u[1] - t[1] * u[0]]])


def _sampson(xa: np.ndarray, xb: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Sampson distances (k, N) (normalised image units) of the correspondences xa <-> xb (N, 3) for
    each of k poses (R (k, 3, 3), t (k, 3)): E = [t]x R."""
    E = skew(t) @ R
    Ex, Etx = xa @ E.transpose(0, 2, 1), xb @ E  # E xa and E^T xb, (k, N, 3)
    return (xb * Ex).sum(2) / np.sqrt(Ex[..., 0] ** 2 + Ex[..., 1] ** 2 + Etx[..., 0] ** 2 + Etx[..., 1] ** 2)


def essential_pose(pa: np.ndarray, pb: np.ndarray, K: np.ndarray, px: float
                   ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray] | None:
    """RANSAC essential matrix and the pose it holds (inliers, R, t, mask), or None when the matches
    give none: OpenCV 5 raises on some degenerate samples (solvePoly's zero leading coefficient)
    where 4.x returned no matrix, and either way the pair has no essential matrix."""
    try:
        E, mask = cv2.findEssentialMat(pa, pb, K, cv2.RANSAC, 0.999, px)
        if E is None or E.shape != (3, 3):
            return None
        inliers, R, t, mask = cv2.recoverPose(E, pa, pb, K, mask=mask)
    except cv2.error:
        return None
    return int(inliers), R, t, mask


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices [v]x of vectors (N, 3)."""
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return K


def rotation_matrices(w: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors (N, 3) (Rodrigues)."""
    theta = np.linalg.norm(w, axis=1)[:, None, None]
    K = skew(w)
    small = theta < 1e-8
    a = np.where(small, 1.0, np.sin(theta) / np.where(small, 1.0, theta))
    b = np.where(small, 0.5, (1 - np.cos(theta)) / np.where(small, 1.0, theta ** 2))
    return np.eye(3)[None] + a * K + b * (K @ K)


def triangulate(K: np.ndarray, rel: Relative) -> np.ndarray:
    """The inlier matches' points in the reference camera's axes for a baseline of length 1."""
    P_ref = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P_other = K @ np.hstack([rel.R, rel.t.reshape(3, 1)])
    X = cv2.triangulatePoints(P_ref, P_other, rel.ref_px.T.astype(np.float64), rel.other_px.T.astype(np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        return (X[:3] / X[3]).T
