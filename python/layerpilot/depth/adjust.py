"""Bundle adjustment of a flight's photos: one consistent block instead of one scale per pair.

Pairwise refinement takes each pair's baseline length from two GNSS positions that are
decimetres to metres off: depth error = depth x baseline error / baseline, so every pair's
cloud sits at its own height. Here features are matched between every two photos that can
overlap, each match set is verified with an essential matrix, the matches are chained into
tracks (a ground point seen in two to six photos), and all camera poses (and, if configured, a
common focal-length factor) and track points are refined together by minimising the
reprojection error with ``scipy.optimize.least_squares`` (robust loss, sparse Jacobian). The
GNSS positions and the attitudes are soft priors: the block's position, orientation and scale
come from all photos together, no single baseline decides a pair's scale.

The recorded heading can be half a turn off (the Brighton Beach flight's second line): for each
verified pair the four combinations of "heading as recorded / turned half a turn" of its two
photos are compared with what the images say, and each photo takes the majority of its pairs'
votes before the adjustment starts.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Sequence

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from layerpilot.geometry import CameraFrame, Pose
from layerpilot.depth.config import AdjustConfig
from layerpilot.depth.refine import HALF_TURN, PoseRefiner, angle_deg, essential_pose


@dataclass(frozen=True)
class PairLink:
    """A verified photo pair: inlier keypoint indices and the heading hypothesis the images preferred."""

    i: int
    j: int
    kp_i: np.ndarray
    kp_j: np.ndarray
    matches: int
    flips: tuple[bool, bool]  # (photo i turned, photo j turned) that best explains the images
    rotation_deg: float  # disagreement with the (turned) attitudes under that hypothesis
    direction_deg: float


@dataclass(frozen=True)
class Adjustment:
    """The adjusted frames (``None`` for photos no verified pair reached) and what the solver did."""

    frames: list[CameraFrame | None]
    flipped: list[bool]
    links: list[PairLink]
    tracks: int
    observations: int
    rms_before_px: float  # reprojection error of the inlier observations, working-scale pixels
    rms_after_px: float
    rms_per_photo_px: list[float]
    lens: tuple[float, float, float]  # focal-length factor, k1, k2 (1, 0, 0 when not fitted)
    position_shift_m: list[float]  # how far each adjusted camera moved from its GNSS position (NaN: not adjusted)


def _turned(frame: CameraFrame, flip: bool) -> np.ndarray:
    return HALF_TURN @ frame.pose.rotation if flip else frame.pose.rotation


def _heading_votes(ra: np.ndarray, rb: np.ndarray, ca: np.ndarray, cb: np.ndarray, R: np.ndarray,
                   t: np.ndarray) -> tuple[tuple[bool, bool], float, float]:
    """The (flip a, flip b) that best matches the images' relative pose (x_b = R x_a + t), and its errors."""
    best = None
    for fa in (False, True):
        for fb in (False, True):
            Ra = HALF_TURN @ ra if fa else ra
            Rb = HALF_TURN @ rb if fb else rb
            tg = Rb.T @ (ca - cb)
            rot = angle_deg((Rb.T @ Ra).T @ R)
            direction = math.degrees(math.acos(float(np.clip(t @ tg / np.linalg.norm(tg), -1.0, 1.0))))
            score = rot + direction
            if best is None or score < best[0]:
                best = (score, (fa, fb), rot, direction)
    return best[1], best[2], best[3]


class BundleAdjuster:
    """Matches, chains and adjusts the photos of one flight (frames in flight order)."""

    def __init__(self, config: AdjustConfig, refiner: PoseRefiner) -> None:
        self.config = config
        self.refiner = refiner
        self._matcher = cv2.FlannBasedMatcher({"algorithm": 1, "trees": 4}, {"checks": 64})  # KD-tree
        # (id(a), id(b)) -> (a, b, link): a live flight adjusts overlapping windows, each photo pair is
        # verified once; holding the frames keeps their ids from being reused. 0 = no cache.
        self._links: OrderedDict[tuple[int, int], tuple[CameraFrame, CameraFrame, PairLink | None]] = OrderedDict()
        self.link_cache = 0

    def match_indices(self, a: CameraFrame, b: CameraFrame) -> tuple[np.ndarray, np.ndarray]:
        """Keypoint indices of the ratio-test matches of two photos (approximate nearest neighbours)."""
        (_, da), (_, db) = self.refiner.features(a), self.refiner.features(b)
        if len(da) < 2 or len(db) < 2:
            return np.zeros(0, int), np.zeros(0, int)
        ratio = self.refiner.config.ratio
        good = [m for m, n in (p for p in self._matcher.knnMatch(da, db, k=2) if len(p) == 2)
                if m.distance < ratio * n.distance]
        return np.array([m.queryIdx for m in good], int), np.array([m.trainIdx for m in good], int)

    def candidate_pairs(self, frames: Sequence[CameraFrame]) -> list[tuple[int, int]]:
        """Photo pairs close enough to overlap: centres within ``overlap_ratio`` x the mean height above ground."""
        c = np.array([f.pose.position for f in frames])
        reach = self.config.overlap_ratio * max(float(np.median(c[:, 2])), 1.0)
        return [(i, j) for i in range(len(frames)) for j in range(i + 1, len(frames))
                if np.linalg.norm(c[i, :2] - c[j, :2]) <= reach]

    def link(self, a: CameraFrame, b: CameraFrame, i: int, j: int) -> PairLink | None:
        """Verify the matches of photos ``i`` and ``j``; None if too few survive.

        First all ratio-test matches go to the essential matrix; when that fails (the forest: a
        tenth of the matches fit, and a wrong model), only the matches near the epipolar lines
        the GNSS/attitude poses predict (``guide_px``) are tried."""
        ia, ib = self.match_indices(a, b)
        if len(ia) < self.config.min_inliers:
            return None
        link = self._verify(a, b, i, j, ia, ib, len(ia))
        if link is None and self.config.guide_px > 0:
            pa, pb = self.refiner.features(a)[0][ia], self.refiner.features(b)[0][ib]
            near = max((_epipolar_px(a.pose.rotation, _turned(b, flip), a.pose.position, b.pose.position, a.K, pa, pb)
                        <= self.config.guide_px for flip in (False, True)), key=np.sum)
            link = self._verify(a, b, i, j, ia[near], ib[near], len(ia))
        return link

    def _cached_link(self, frames: Sequence[CameraFrame], i: int, j: int) -> PairLink | None:
        if not self.link_cache:
            return self.link(frames[i], frames[j], i, j)
        key = (id(frames[i]), id(frames[j]))
        if key not in self._links:
            self._links[key] = (frames[i], frames[j], self.link(frames[i], frames[j], i, j))
            while len(self._links) > self.link_cache:
                self._links.popitem(last=False)
        link = self._links[key][2]
        return None if link is None else replace(link, i=i, j=j)

    def _verify(self, a: CameraFrame, b: CameraFrame, i: int, j: int, ia: np.ndarray, ib: np.ndarray,
                matches: int) -> PairLink | None:
        c = self.config
        if len(ia) < c.min_inliers:
            return None
        pa, pb = self.refiner.features(a)[0][ia], self.refiner.features(b)[0][ib]
        if (found := essential_pose(pa, pb, a.K, c.ransac_px)) is None:
            return None
        inliers, R, t, mask = found
        keep = mask.ravel() > 0
        if inliers < max(c.min_inliers, c.min_inlier_ratio * len(ia)):
            return None
        flips, rot, direction = _heading_votes(a.pose.rotation, b.pose.rotation, a.pose.position, b.pose.position,
                                               R, t.ravel())
        if rot > c.max_rotation_deg or direction > c.max_direction_deg:
            return None
        return PairLink(i, j, ia[keep], ib[keep], matches, flips, rot, direction)

    def adjust(self, frames: Sequence[CameraFrame]) -> Adjustment:
        """Adjusted copies of ``frames``; photos without a verified pair are ``None``."""
        n = len(frames)
        links = [lk for i, j in self.candidate_pairs(frames) if (lk := self._cached_link(frames, i, j))]
        votes = np.zeros((n, 2))
        for lk in links:
            w = len(lk.kp_i)
            votes[lk.i, int(lk.flips[0])] += w
            votes[lk.j, int(lk.flips[1])] += w
        flipped = [bool(v[1] > v[0]) for v in votes]
        links = [lk for lk in links if lk.flips == (flipped[lk.i], flipped[lk.j])]  # drop pairs that disagree
        cams, pts, uv = self._tracks(frames, links)
        used = sorted(set(cams.tolist()))
        if len(used) < 2:
            return Adjustment([None] * n, flipped, links, 0, 0, math.nan, math.nan, [math.nan] * n, (1.0, 0.0, 0.0),
                              [math.nan] * n)
        R0 = np.array([_turned(f, fl) for f, fl in zip(frames, flipped)])
        gnss = np.array([f.pose.position for f in frames])
        K = frames[0].K
        X0 = _triangulate(R0, gnss, K, cams, pts, uv, int(pts.max()) + 1)
        rvec, centres, (focal, k1, k2), rms0, rms1, per_cam = self._solve(R0, gnss, K, cams, pts, uv, X0, used)
        out: list[CameraFrame | None] = [None] * n
        for k in used:
            R = Rotation.from_rotvec(rvec[k]).as_matrix() @ R0[k]
            intr = replace(frames[k].intrinsics, fx=frames[k].intrinsics.fx * focal,
                           fy=frames[k].intrinsics.fy * focal)
            image = (cv2.undistort(frames[k].image, intr.K, np.array([k1, k2, 0.0, 0.0])) if k1 or k2
                     else frames[k].image)
            out[k] = replace(frames[k], image=image, pose=Pose.from_rotation(R, centres[k]), intrinsics=intr)
        shifts = [float(np.linalg.norm(centres[k] - gnss[k])) if k in used else math.nan for k in range(n)]
        return Adjustment(out, flipped, links, int(pts.max()) + 1, len(cams), rms0, rms1, per_cam,
                          (float(focal), float(k1), float(k2)), shifts)

    def _tracks(self, frames: Sequence[CameraFrame], links: list[PairLink]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Chain the pairs' inlier matches into tracks: (camera, track, pixel) per observation.

        A track that would hold two different keypoints of one photo is dropped (an ambiguous chain)."""
        feats = [self.refiner.features(f)[0] for f in frames]
        offset = np.cumsum([0] + [len(p) for p in feats])
        parent = np.arange(offset[-1])

        def find(x: int) -> int:
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        for lk in links:
            for a, b in zip(offset[lk.i] + lk.kp_i, offset[lk.j] + lk.kp_j):
                ra, rb = find(int(a)), find(int(b))
                if ra != rb:
                    parent[rb] = ra
        nodes = np.unique(np.concatenate([np.concatenate([offset[lk.i] + lk.kp_i, offset[lk.j] + lk.kp_j])
                                          for lk in links])) if links else np.zeros(0, int)
        roots = np.array([find(int(x)) for x in nodes], int)
        cam = np.searchsorted(offset, nodes, side="right") - 1
        # a track is valid when it has >= 2 photos and each photo once
        order = np.lexsort((cam, roots))
        roots, cam, nodes = roots[order], cam[order], nodes[order]
        same = (roots[1:] == roots[:-1]) & (cam[1:] == cam[:-1])
        bad_roots = set(roots[1:][same].tolist())
        _, first, counts = np.unique(roots, return_index=True, return_counts=True)
        small = set(roots[first[counts < self.config.min_track]].tolist())
        dup = np.isin(roots, list(bad_roots | small))
        roots, cam, nodes = roots[~dup], cam[~dup], nodes[~dup]
        _, track = np.unique(roots, return_inverse=True)
        uv = np.array([feats[c][x - offset[c]] for c, x in zip(cam, nodes)], np.float64).reshape(-1, 2)
        return cam.astype(int), track.astype(int), uv

    def _solve(self, R0: np.ndarray, gnss: np.ndarray, K: np.ndarray, cams: np.ndarray, pts: np.ndarray,
               uv: np.ndarray, X0: np.ndarray, used: list[int]):
        """Poses, lens (focal factor, k1, k2) and points minimising robust reprojection error plus the priors."""
        c = self.config
        n, m = len(R0), len(X0)
        lens_sigma = np.array([c.focal_sigma, c.distortion_sigma, c.distortion_sigma])
        fitted = np.flatnonzero(lens_sigma > 0)  # which of the lens parameters are free
        nl = len(fitted)
        sig_pos = np.array([c.gnss_sigma_h, c.gnss_sigma_h, c.gnss_sigma_v])
        sig_rot = np.radians([c.tilt_sigma_deg, c.tilt_sigma_deg, c.yaw_sigma_deg])  # map-frame x, y (tilt), z (yaw)
        f0, cx, cy = K[0, 0], K[0, 2], K[1, 2]
        used_mask = np.zeros(n, bool)
        used_mask[used] = True
        lens0 = np.array([1.0, 0.0, 0.0])

        def unpack(x: np.ndarray):
            cam = x[:6 * n].reshape(n, 6)
            lens = lens0.copy()
            lens[fitted] = x[6 * n:6 * n + nl]
            return cam[:, :3], cam[:, 3:], lens, x[6 * n + nl:].reshape(m, 3)

        def reprojection(x: np.ndarray) -> np.ndarray:
            rvec, centre, (focal, k1, k2), X = unpack(x)
            R = Rotation.from_rotvec(rvec).as_matrix() @ R0  # camera -> map
            local = np.einsum("nji,nj->ni", R[cams], X[pts] - centre[cams])  # R^T (X - C)
            xy = local[:, :2] / local[:, 2:3]
            r2 = (xy ** 2).sum(1, keepdims=True)
            proj = f0 * focal * xy * (1.0 + k1 * r2 + k2 * r2 * r2) + (cx, cy)
            return ((proj - uv) / c.pixel_sigma).ravel()

        def residuals(x: np.ndarray) -> np.ndarray:
            rvec, centre, lens, _ = unpack(x)
            return np.concatenate([reprojection(x), ((centre - gnss) / sig_pos)[used_mask].ravel(),
                                   (rvec / sig_rot)[used_mask].ravel(), (lens - lens0)[fitted] / lens_sigma[fitted]])

        x0 = np.concatenate([np.hstack([np.zeros((n, 3)), gnss]).ravel(), lens0[fitted], X0.ravel()])
        n_obs, n_used = len(cams), len(used)
        rows = 2 * n_obs + 6 * n_used + nl
        sparsity = lil_matrix((rows, len(x0)), dtype=np.int8)
        obs = np.arange(n_obs)
        for parity in (0, 1):
            for k in range(6):
                sparsity[2 * obs + parity, 6 * cams + k] = 1
            for k in range(3):
                sparsity[2 * obs + parity, 6 * n + nl + 3 * pts + k] = 1
        for k in range(nl):
            sparsity[:2 * n_obs, 6 * n + k] = 1
            sparsity[rows - nl + k, 6 * n + k] = 1
        for r, k in enumerate(used):
            for d in range(3):
                sparsity[2 * n_obs + 3 * r + d, 6 * k + 3 + d] = 1  # position prior
                sparsity[2 * n_obs + 3 * n_used + 3 * r + d, 6 * k + d] = 1  # attitude prior
        rms0 = _rms(reprojection(x0) * c.pixel_sigma)
        sol = least_squares(residuals, x0, jac_sparsity=sparsity, loss=c.loss, f_scale=c.loss_scale,
                            x_scale="jac", method="trf", max_nfev=c.max_evaluations, xtol=1e-10, ftol=1e-8)
        rvec, centre, lens, _ = unpack(sol.x)
        res = reprojection(sol.x) * c.pixel_sigma
        per_cam = [_rms(res.reshape(-1, 2)[cams == k].ravel()) for k in range(n)]
        return rvec, centre, lens, rms0, _rms(res), per_cam


def _rms(residuals: np.ndarray, clip: float = 10.0) -> float:
    """Root mean square of pixel residuals, each clipped at ``clip`` (outliers would dominate otherwise)."""
    r = np.minimum(np.abs(residuals), clip)
    return float(np.sqrt(np.mean(r ** 2))) if len(r) else math.nan


def _epipolar_px(Ra: np.ndarray, Rb: np.ndarray, ca: np.ndarray, cb: np.ndarray, K: np.ndarray, pa: np.ndarray,
                 pb: np.ndarray) -> np.ndarray:
    """Distance (pixels) of each ``pb`` from the epipolar line of its ``pa`` for cameras (Ra, ca) and (Rb, cb)."""
    t = Rb.T @ (ca - cb)
    E = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) @ (Rb.T @ Ra)
    Ki = np.linalg.inv(K)
    lines = np.column_stack([pa, np.ones(len(pa))]) @ (Ki.T @ E @ Ki).T
    return np.abs((lines[:, :2] * pb).sum(1) + lines[:, 2]) / np.linalg.norm(lines[:, :2], axis=1)


def _triangulate(R: np.ndarray, C: np.ndarray, K: np.ndarray, cams: np.ndarray, pts: np.ndarray, uv: np.ndarray,
                 m: int) -> np.ndarray:
    """Each track's point nearest (least squares) to its viewing rays."""
    rays = np.column_stack([(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1], np.ones(len(uv))])
    d = np.einsum("nij,nj->ni", R[cams], rays)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    P = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    A = np.zeros((m, 3, 3))
    b = np.zeros((m, 3))
    np.add.at(A, pts, P)
    np.add.at(b, pts, np.einsum("nij,nj->ni", P, C[cams]))
    return np.linalg.solve(A + 1e-9 * np.eye(3)[None], b[:, :, None])[:, :, 0]
