"""The vehicle's state, true and as its autopilot's EKF reports it (the truth plus :class:`PoseErrors`)."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from layerpilot.sim.pose_errors import PoseErrors
from layerpilot.sim.sensors import SensorProfile

HISTORY_S = 3.0  # seconds of reported states kept for look-ups at a camera stamp


@dataclass(frozen=True)
class VehiclePose:
    """Vehicle state in the map frame (ENU) at mission time ``time``; angles in radians, yaw CCW from east."""

    time: float
    position: np.ndarray
    velocity: np.ndarray
    roll: float
    pitch: float
    yaw: float


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class Estimator:
    """What the EKF reports: each step the true state plus that step's error, kept for ``HISTORY_S``."""

    def __init__(self, profile: SensorProfile, seed: int) -> None:
        self._profile, self._seed = profile, seed
        self.errors = self._seeded_errors()
        self._exact = profile.exact_pose
        self._history: deque[VehiclePose] = deque()

    def _seeded_errors(self) -> PoseErrors:
        return PoseErrors(self._profile, np.random.default_rng([self._seed, 1]))

    def restart(self, truth: VehiclePose) -> None:
        """The errors from their seed again and the history from ``truth`` on: a lock-step mission's clock
        starts after a wall-paced take-off of varying length, and its errors must not depend on it."""
        self.errors = self._seeded_errors()
        self._history.clear()
        self._history.append(truth if self._exact else self.report(truth))

    def step(self, dt: float, truth: VehiclePose) -> None:
        if not self._exact:  # exact: the errors stay zero; only the history is kept (a camera stamp's look-up)
            self.errors.step(dt)
        self._history.append(truth if self._exact else self.report(truth))
        while self._history[0].time < truth.time - HISTORY_S:
            self._history.popleft()

    def report(self, truth: VehiclePose) -> VehiclePose:
        """``truth`` with the current error (velocity is reported exact)."""
        e = self.errors.current
        return VehiclePose(truth.time, truth.position + e.position, truth.velocity.copy(), truth.roll + e.roll,
                           truth.pitch + e.pitch, _wrap(truth.yaw + e.yaw))

    def at(self, t: float) -> VehiclePose | None:
        """The reported state at ``t`` as a camera node finds it: linear between the two reports around
        ``t``, extrapolated from the last two outside them (None before the first step)."""
        h = self._history
        if len(h) < 2:
            return h[-1] if h else None
        times = [p.time for p in h]
        i = int(np.clip(np.searchsorted(times, t), 1, len(h) - 1))
        a, b = h[i - 1], h[i]
        w = (t - a.time) / (b.time - a.time)
        return VehiclePose(t, a.position + w * (b.position - a.position), a.velocity + w * (b.velocity - a.velocity),
                           a.roll + w * (b.roll - a.roll), a.pitch + w * (b.pitch - a.pitch),
                           _wrap(a.yaw + w * _wrap(b.yaw - a.yaw)))
