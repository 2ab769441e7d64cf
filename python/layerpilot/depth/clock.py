"""The telemetry pose stream and the camera's clock offset against it, learnt from the images.

A frame is stamped on the camera's clock; the vehicle's poses on the telemetry's. A camera
whose clock is ``offset`` seconds behind exposed the frame stamped ``t`` when the telemetry
said ``t + offset``. The images measure how the camera turned between two frames (the pair's
relative rotation, a few hundredths of a degree); the telemetry says how it turned between any
two times. For every refined pair the disagreement is computed once for every candidate offset
on a grid (``max_offset`` each way, ``step`` apart) and added to a running cost; the estimate is
the cost's minimum, refined by a parabola through its neighbours. Pairs over which the camera
did not turn carry no information (every offset fits them equally) and leave the cost's shape
alone; the estimate is reported once ``min_pairs`` informative pairs have been seen.
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from layerpilot.config import check_range
from layerpilot.geometry import Pose


class PoseHistory:
    """The newest ``seconds`` of a stamped pose stream; poses between samples by slerp (rotation) and
    linear interpolation (position); None in a gap longer than ``max_gap`` or outside the stream."""

    def __init__(self, seconds: float = 60.0, max_gap: float = 0.5) -> None:
        check_range("seconds", seconds, 1.0)
        check_range("max_gap", max_gap, 1e-3)
        self.seconds, self.max_gap = seconds, max_gap
        self.stamps: list[float] = []
        self.poses: list[Pose] = []

    def add(self, stamp: float, pose: Pose) -> None:
        """A pose of the stream; a late one is put in order, a repeated stamp ignored."""
        if not math.isfinite(stamp):
            raise ValueError(f"stamp: {stamp} is not finite")
        i = bisect.bisect_left(self.stamps, stamp)
        if i < len(self.stamps) and self.stamps[i] == stamp:
            return
        self.stamps.insert(i, stamp)
        self.poses.insert(i, pose)
        cut = bisect.bisect_left(self.stamps, self.stamps[-1] - self.seconds)
        del self.stamps[:cut], self.poses[:cut]

    def covers(self, t0: float, t1: float) -> bool:
        """True when [t0, t1] lies inside the stream without a gap longer than ``max_gap``."""
        if not self.stamps or t0 < self.stamps[0] or t1 > self.stamps[-1]:
            return False
        i, j = bisect.bisect_left(self.stamps, t0), bisect.bisect_right(self.stamps, t1)
        window = self.stamps[max(i - 1, 0):j + 1]
        return len(window) < 2 or max(np.diff(window), default=0.0) <= self.max_gap

    def rotations(self, times: np.ndarray) -> Rotation:
        """The stream's rotations at ``times`` (all inside it: check ``covers`` first)."""
        return Slerp(self.stamps, Rotation.from_matrix([p.rotation for p in self.poses]))(times)

    def at(self, t: float, ahead: float = 0.0) -> Pose | None:
        """The pose at ``t``, or None outside the stream or in a gap. Up to ``ahead`` seconds past the
        newest sample the position goes on at the last velocity and the rotation stays the last one:
        a frame stamped just after the telemetry's newest pose is still placed on the telemetry's clock."""
        if self.stamps and self.stamps[-1] < t <= self.stamps[-1] + ahead:
            return self._extrapolated(t)
        if not self.covers(t, t):
            return None
        i = bisect.bisect_left(self.stamps, t)
        if self.stamps[i] == t:
            return self.poses[i]
        t0, t1 = self.stamps[i - 1], self.stamps[i]
        s = (t - t0) / (t1 - t0)
        a, b = self.poses[i - 1], self.poses[i]
        R = Slerp([0.0, 1.0], Rotation.from_matrix([a.rotation, b.rotation]))([s]).as_matrix()[0]
        return Pose.from_rotation(R, a.position + s * (b.position - a.position))

    def _extrapolated(self, t: float) -> Pose:
        last = self.poses[-1]
        if len(self.stamps) < 2 or self.stamps[-1] - self.stamps[-2] > self.max_gap:
            return last
        velocity = (last.position - self.poses[-2].position) / (self.stamps[-1] - self.stamps[-2])
        return Pose(last.position + velocity * (t - self.stamps[-1]), last.orientation)


class TimeOffset:
    """Running estimate of the camera clock's offset from the telemetry's (seconds, added to a frame's stamp)."""

    def __init__(self, max_offset: float = 0.5, step: float = 0.005, min_pairs: int = 5,
                 min_turn_deg: float = 0.3, cap_deg: float = 1.0) -> None:
        check_range("max_offset", max_offset, 0.0, 10.0)
        check_range("step", step, 1e-4, max(max_offset, 1e-4))
        check_range("min_pairs", min_pairs, 1)
        self.grid = np.arange(-max_offset, max_offset + step / 2, step)
        self.cost = np.zeros(len(self.grid))
        self.min_pairs, self.min_turn, self.cap = min_pairs, math.radians(min_turn_deg), math.radians(cap_deg)
        self.pending: list[tuple[float, float, np.ndarray]] = []
        self.pairs = 0  # informative pairs in the cost

    def add(self, t_ref: float, t_other: float, rotation: np.ndarray) -> None:
        """The images' relative camera rotation of a pair (``x_other = R x_ref``), stamps on the camera clock."""
        self.pending.append((t_ref, t_other, np.asarray(rotation, np.float64)))

    def update(self, cameras: PoseHistory) -> None:
        """Add the pending pairs whose times (plus any offset on the grid) the camera pose stream covers."""
        keep = []
        lo, hi = self.grid[0], self.grid[-1]
        for t_ref, t_other, R in self.pending:
            t0, t1 = min(t_ref, t_other) + lo, max(t_ref, t_other) + hi
            if not cameras.covers(t0, t1):
                if cameras.stamps and t1 > cameras.stamps[-1]:
                    keep.append((t_ref, t_other, R))  # its poses have not all arrived yet
                continue
            ref, other = cameras.rotations(t_ref + self.grid), cameras.rotations(t_other + self.grid)
            err = (Rotation.from_matrix(R).inv() * (other.inv() * ref)).magnitude()  # images vs telemetry per offset
            if err.max() - err.min() < self.min_turn:
                continue  # the camera did not turn enough to tell offsets apart
            self.cost += np.minimum(err, self.cap) ** 2
            self.pairs += 1
        self.pending = keep

    @property
    def estimate(self) -> float | None:
        """The offset (s) with the smallest cost, between grid points; None before ``min_pairs`` informative pairs."""
        if self.pairs < self.min_pairs:
            return None
        i = int(np.argmin(self.cost))
        if 0 < i < len(self.grid) - 1:
            a, b, c = self.cost[i - 1:i + 2]
            curvature = a - 2 * b + c
            shift = 0.5 * (a - c) / curvature if curvature > 0 else 0.0
            return float(self.grid[i] + np.clip(shift, -0.5, 0.5) * (self.grid[1] - self.grid[0]))
        return float(self.grid[i])
