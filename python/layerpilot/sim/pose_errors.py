"""The autopilot's estimation error: what its EKF reports minus the truth, stepped with the mission clock.

Each error is a first-order Gauss-Markov process started from its stationary
distribution, so its statistics hold from the first step: standard deviation sigma,
autocorrelation exp(-|dt| / tau). Barometric drift grows linearly with time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from layerpilot.sim.sensors import SensorProfile


class GaussMarkov:
    """x(t + dt) = a x(t) + sigma sqrt(1 - a^2) w, a = exp(-dt / tau), w ~ N(0, 1): exact for any dt."""

    def __init__(self, sigma: float, tau: float, rng: np.random.Generator, size: int = 1) -> None:
        self.sigma, self.tau, self._rng = sigma, tau, rng
        self.value = rng.normal(0.0, sigma, size)

    def step(self, dt: float) -> np.ndarray:
        a = math.exp(-dt / self.tau)
        self.value = a * self.value + self.sigma * math.sqrt(1.0 - a * a) * self._rng.normal(0.0, 1.0, self.value.size)
        return self.value


@dataclass(frozen=True)
class NavError:
    """Reported minus true: map-frame position (m, ENU) and attitude (rad); ``drift`` leaves out the white noise."""

    position: np.ndarray
    drift: np.ndarray
    gnss: np.ndarray  # the receiver's own error (GPS_RAW_INT): no baro drift, no EKF
    roll: float
    pitch: float
    yaw: float


class PoseErrors:
    """The EKF's errors of one flight, from its own seeded generator (the same seed, the same errors)."""

    def __init__(self, profile: SensorProfile, rng: np.random.Generator) -> None:
        p = self.profile = profile
        self._rng = rng
        self._horizontal = GaussMarkov(p.horizontal_sigma_m, p.horizontal_tau_s, rng, 2)
        self._vertical = GaussMarkov(p.vertical_sigma_m, p.vertical_tau_s, rng)
        self._tilt = GaussMarkov(math.radians(p.tilt_sigma_deg), p.tilt_tau_s, rng, 2)
        self._heading = GaussMarkov(math.radians(p.heading_sigma_deg), p.heading_tau_s, rng)
        self._baro_rate = p.baro_drift_m_per_min / 60.0 * (1.0 if rng.random() < 0.5 else -1.0)
        self._elapsed = 0.0
        self.current = self._compose(np.zeros(2))

    def step(self, dt: float) -> NavError:
        """Advance ``dt`` seconds; returns (and keeps as ``current``) the new error."""
        self._elapsed += dt
        for process in (self._horizontal, self._vertical, self._tilt, self._heading):
            process.step(dt)
        self.current = self._compose(self._rng.normal(0.0, self.profile.horizontal_white_m, 2))
        return self.current

    def _compose(self, white: np.ndarray) -> NavError:
        gnss = np.array([*self._horizontal.value, self._vertical.value[0]])
        drift = gnss + [0.0, 0.0, self._baro_rate * self._elapsed]
        roll, pitch = self._tilt.value
        return NavError(drift + [white[0], white[1], 0.0], drift, gnss, float(roll), float(pitch),
                        float(self._heading.value[0]) + math.radians(self.profile.heading_bias_deg))
