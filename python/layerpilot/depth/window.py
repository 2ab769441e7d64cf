"""Sliding-window adjustment of the recent camera poses: the trajectory's shape from the images,
its place from GNSS and attitude.

Every refined pair adds an edge between its two keyframes: the images' relative rotation, the
baseline's direction and - when the partner's points were seen again - the baseline's length,
carried over from the partner's earlier pair (monocular scale transfer: the same ground points
triangulated twice give the ratio of the two baselines). Each keyframe keeps its reported pose
as a prior (GNSS position, attitude). The last ``size`` keyframes are solved together, rotations
and centres at once, by Huber-reweighted Gauss-Newton (a sparse linear solve per iteration: a few
milliseconds, where scipy's least_squares took hundreds); older ones keep their last estimate. A
single pair takes its baseline's length from two GNSS fixes a second apart, whose wandering errors
do not cancel; the window spreads that error over its whole length instead, and sees a heading
bias that no single pair can in the GNSS track.
"""

from __future__ import annotations

import math
import warnings
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csc_matrix
from scipy.sparse.linalg import MatrixRankWarning, spsolve

from layerpilot.config import check_range
from layerpilot.depth.refine import Relative, rotation_matrices, skew
from layerpilot.geometry import Pose, quat_from_matrix


@dataclass(frozen=True)
class WindowConfig:
    """Sigmas of the window's measurements and priors (see docs/depth.md, "Pose refinement")."""

    size: int = 20  # keyframes solved together
    rotation_sigma_deg: float = 0.05  # the images' relative rotation
    direction_sigma_deg: float = 0.5  # ... and baseline direction
    length_sigma: float = 0.02  # relative error of a transferred baseline length
    gnss_sigma_h: float = 2.0  # m, position prior per axis
    gnss_sigma_v: float = 4.0
    delta_sigma_h: float = 0.2  # m per axis: the GNSS displacement between keyframes a second apart ...
    delta_sigma_v: float = 0.3  # ... (the wandering error is common to both fixes; grows as sqrt(1 + dt))
    tilt_sigma_deg: float = 1.0  # attitude prior: roll and pitch ...
    yaw_sigma_deg: float = 10.0  # ... and heading: a bias does not average out over the window, GNSS's track sees it
    loss_scale: float = 3.0  # residuals beyond this many sigmas are down-weighted (soft L1)

    def __post_init__(self) -> None:
        check_range("size", self.size, 2, 500)
        for name in ("rotation_sigma_deg", "direction_sigma_deg", "length_sigma", "gnss_sigma_h", "gnss_sigma_v",
                     "delta_sigma_h", "delta_sigma_v", "tilt_sigma_deg", "yaw_sigma_deg", "loss_scale"):
            check_range(name, getattr(self, name), 1e-6)


@dataclass
class Keyframe:
    """A frame in the window: its reported pose, its estimate, and its triangulated points (camera axes, metres)."""

    stamp: float
    prior: Pose
    pose: Pose
    points_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float32))
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass(frozen=True)
class Edge:
    """A refined pair: ``ref`` (newer) and ``other`` keyframe stamps, the images' relative pose and the
    baseline length (NaN: direction only)."""

    ref: float
    other: float
    relative: Relative
    length: float


class SlidingWindow:
    """The last ``size`` keyframes and the edges between them, adjusted on every new edge (the oldest
    keyframes leave when an edge is added)."""

    def __init__(self, config: WindowConfig = WindowConfig()) -> None:
        self.config = config
        self.frames: dict[float, Keyframe] = {}
        self.order: deque[float] = deque()
        self.edges: list[Edge] = []

    def keyframe(self, stamp: float, prior: Pose) -> Keyframe:
        """The keyframe of ``stamp``, added (estimate = prior) if new."""
        if stamp not in self.frames:
            self.frames[stamp] = Keyframe(stamp, prior, prior)
            self.order.append(stamp)
        return self.frames[stamp]

    def add(self, edge: Edge) -> bool:
        """Add a pair between two keyframes already in the window and adjust; False (and the edge
        left out, the estimates unchanged) when the adjustment does not give finite poses."""
        if edge.ref not in self.frames or edge.other not in self.frames:
            raise ValueError("edge: both keyframes must be in the window")
        self.edges.append(edge)
        while len(self.order) > self.config.size:  # the oldest keyframes leave, never the new edge's own
            gone = next(s for s in self.order if s not in (edge.ref, edge.other))
            self.order.remove(gone)
            del self.frames[gone]
            self.edges = [e for e in self.edges if gone not in (e.ref, e.other)]
        if not self.solve():
            self.edges.pop()
            return False
        return True

    def solve(self, iterations: int = 4) -> bool:
        """Re-estimate every keyframe in the window from the edges and the priors: Gauss-Newton on the
        rotation corrections (map axes, ``R <- exp(w) R``) and centres together, robustly reweighted."""
        stamps = list(self.order)
        index = {s: k for k, s in enumerate(stamps)}
        ref = np.array([index[e.ref] for e in self.edges], int)
        other = np.array([index[e.other] for e in self.edges], int)
        R = np.array([self.frames[s].pose.rotation for s in stamps])
        C = np.array([self.frames[s].pose.position for s in stamps])
        prior_R = np.array([self.frames[s].prior.rotation for s in stamps])
        prior_C = np.array([self.frames[s].prior.position for s in stamps])
        edges = self._edge_terms()
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", MatrixRankWarning)
            for _ in range(iterations):
                step = self._step(R, C, prior_R, prior_C, ref, other, edges)
                if not np.isfinite(step).all():
                    return False
                R, C = rotation_matrices(step[:, :3]) @ R, C + step[:, 3:]
                if np.abs(step[:, :3]).max() < 1e-6 and np.abs(step[:, 3:]).max() < 1e-3:  # 0.00006 deg, 1 mm
                    break
        for s, Rk, Ck in zip(stamps, R, C):
            # products of exact rotations: orthonormal to rounding, so Pose.from_rotation's checks are skipped
            self.frames[s].pose = Pose(Ck, quat_from_matrix(Rk))
        return True

    def _edge_terms(self) -> tuple[np.ndarray, ...]:
        """What the edges say, the same in every iteration: the images' relative rotations (m, 3, 3), the
        baseline axes (m, 3 axes, 3: two across the images' direction, then along it), the measured lengths
        (NaN: none) and the sigmas of the GNSS displacements (m, 3)."""
        c = self.config
        t = np.array([e.relative.t for e in self.edges])
        helper = np.where((np.abs(t[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        u = np.cross(t, helper)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        axes = np.stack([u, np.cross(t, u), t], axis=1)
        dt = np.array([abs(e.ref - e.other) for e in self.edges])
        sig_delta = np.sqrt(1.0 + dt)[:, None] * [c.delta_sigma_h, c.delta_sigma_h, c.delta_sigma_v]
        return (np.array([e.relative.R for e in self.edges]), axes, np.array([e.length for e in self.edges]), sig_delta)

    def _step(self, R: np.ndarray, C: np.ndarray, prior_R: np.ndarray, prior_C: np.ndarray, ref: np.ndarray,
              other: np.ndarray, edges: tuple[np.ndarray, ...]) -> np.ndarray:
        """One reweighted Gauss-Newton step (n, 6): rotation correction and centre shift per keyframe."""
        c, n, m = self.config, len(R), len(self.edges)
        rel_R, axes, measured, sig_delta = edges
        sig_rot, sig_dir = math.radians(c.rotation_sigma_deg), math.radians(c.direction_sigma_deg)
        # each edge's rows (rotation, baseline, displacement: 9) touch its two keyframes' 12 columns (ref's, other's)
        J = np.zeros((m, 9, 12))
        # rotation: log(R_meas^T Rj^T Ri) ~ err0 + R_meas^T Rj^T (w_i - w_j)
        M = np.einsum("kba,kcb->kac", rel_R, R[other])
        err0 = _log_small(M @ R[ref])
        w = _huber(np.linalg.norm(err0, axis=1) / sig_rot, c.loss_scale) / sig_rot
        J[:, 0:3, 0:3] = w[:, None, None] * M
        J[:, 0:3, 6:9] = -w[:, None, None] * M
        r_rot = w[:, None] * err0
        # baseline: a^T Rj^T (c_i - c_j) against the images' direction (across: target 0) and length (along)
        b = C[ref] - C[other]
        d = np.einsum("kba,kb->ka", R[other], b)
        has_length = np.isfinite(measured)
        length = np.where(has_length, measured, np.linalg.norm(d, axis=1))
        target = np.zeros((m, 3))
        target[:, 2] = length
        sigma = np.stack([sig_dir * length, sig_dir * length, c.length_sigma * length], axis=1)
        r = np.einsum("kxa,ka->kx", axes, d) - target
        w = _huber(np.abs(r) / sigma, c.loss_scale) / sigma * np.stack([np.ones(m), np.ones(m), has_length], axis=1)
        g = np.einsum("kab,kxb->kxa", R[other], axes)  # Rj a, per axis
        J[:, 3:6, 3:6] = w[:, :, None] * g
        J[:, 3:6, 9:12] = -w[:, :, None] * g
        J[:, 3:6, 6:9] = w[:, :, None] * np.einsum("kxa,kab->kxb", g, skew(b))
        r_base = w * r
        # GNSS displacement: the pair's reported baseline, good to decimetres where the absolute fix is metres
        # off (the receiver's wandering error is common to both fixes)
        r_delta = (b - (prior_C[ref] - prior_C[other])) / sig_delta
        w = _huber(np.abs(r_delta), c.loss_scale) / sig_delta
        J[:, 6:9, 3:6] = w[:, :, None] * np.eye(3)
        J[:, 6:9, 9:12] = -w[:, :, None] * np.eye(3)
        r_delta = w * sig_delta * r_delta
        # priors: attitude (map axes: tilt x, y and heading z) and GNSS position, one diagonal row per unknown
        sig = np.concatenate([np.radians([c.tilt_sigma_deg, c.tilt_sigma_deg, c.yaw_sigma_deg]),
                              [c.gnss_sigma_h, c.gnss_sigma_h, c.gnss_sigma_v]])
        r_prior = np.hstack([_log_small(np.einsum("nij,nkj->nik", R, prior_R)), C - prior_C]) / sig
        # normal equations A^T A x = -A^T r, summed edge by edge (12 x 12 blocks) without a BLAS call
        res = np.concatenate([r_rot, r_base, r_delta], axis=1)  # (m, 9)
        JtJ = np.einsum("kai,kaj->kij", J, J).reshape(m, 2, 6, 2, 6)
        Jtr = np.einsum("kai,ka->ki", J, res).reshape(m, 2, 6)
        N = np.zeros((n, n, 6, 6))
        rhs = (r_prior / sig).ravel()
        ends = (ref, other)
        for a in range(2):
            np.add.at(rhs.reshape(n, 6), ends[a], Jtr[:, a])
            for e in range(2):
                np.add.at(N, (ends[a], ends[e]), JtJ[:, a, :, e])
        N = N.transpose(0, 2, 1, 3).reshape(6 * n, 6 * n)
        N[np.diag_indices_from(N)] += np.tile(1.0 / sig ** 2, n)
        # block-sparse; a sparse solve also stays off the BLAS thread pool, slow on a busy machine
        return spsolve(csc_matrix(N), -rhs).reshape(n, 6)  # the priors keep A^T A well conditioned


def _huber(r: np.ndarray | float, scale: float) -> np.ndarray | float:
    """Square-root Huber weight of normalised residuals ``r``: 1 inside ``scale``, falling as 1/sqrt(r) beyond."""
    return np.sqrt(np.minimum(1.0, scale / np.maximum(r, 1e-12)))


def _log_small(R: np.ndarray) -> np.ndarray:
    """Rotation vectors of rotations (N, 3, 3) a few degrees from identity (the skew part; exact to 0.1 %
    below 5 degrees, and monotonic beyond, which is all a robust residual needs)."""
    return 0.5 * np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
