"""The autopilot's estimation error: what its EKF reports minus the truth, stepped with the mission clock.

Each error is a first-order Gauss-Markov process started from its stationary
distribution, so its statistics hold from the first step: standard deviation sigma,
autocorrelation exp(-|dt| / tau), in addition low-passed over a few seconds, as the
receiver's and the EKF's filters smooth them: a first-order process alone would move like
a random walk from one 10 Hz report to the next, which no EKF output does (the attitude is
the gyros integrated between slow corrections; a random-walk heading error would turn the
degraded profile's telemetry 0.2 degrees between 20 Hz steps and hide the camera's turns
from the clock-offset estimate). The standard deviation stays sigma and the autocorrelation is
exp(-|dt| / tau) beyond a few smoothing times. Barometric drift grows linearly with time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from layerpilot.sim.sensors import SensorProfile


class SmoothedGaussMarkov:
    """A Gauss-Markov process x (time constant tau) through a first-order low-pass y (time constant
    ``smoothing``), scaled so that y's stationary standard deviation is sigma. Stepped exactly for any dt:
    s(t + dt) = Phi s(t) + w, Phi = expm(A dt), cov(w) = P - Phi P Phi^T with P the stationary covariance."""

    def __init__(self, sigma: float, tau: float, smoothing: float, rng: np.random.Generator, size: int = 1) -> None:
        self._rng = rng
        self._a = np.array([[-1.0 / tau, 0.0], [1.0 / smoothing, -1.0 / smoothing]])
        var_x = sigma ** 2 * (tau + smoothing) / tau  # var(y) = var(x) tau / (tau + smoothing)
        cov_xy = var_x * tau / (tau + smoothing)
        self._p = np.array([[var_x, cov_xy], [cov_xy, sigma ** 2]])  # solves A P + P A^T + Q = 0
        self._steps: dict[float, tuple[np.ndarray, np.ndarray]] = {}  # dt -> (Phi, a square root of cov(w))
        self._state = _root(self._p) @ rng.normal(0.0, 1.0, (2, size))  # (2, size): rows x, y

    @property
    def value(self) -> np.ndarray:
        return self._state[1]

    def step(self, dt: float) -> np.ndarray:
        if dt not in self._steps:
            phi = expm(self._a * dt)
            self._steps[dt] = (phi, _root(self._p - phi @ self._p @ phi.T))
        phi, root = self._steps[dt]
        self._state = phi @ self._state + root @ self._rng.normal(0.0, 1.0, self._state.shape)
        return self.value


def _root(cov: np.ndarray) -> np.ndarray:
    """S with S S^T = cov, also for a (nearly) singular covariance: N(0, cov) samples are S @ N(0, I)."""
    w, v = np.linalg.eigh(cov)
    return v * np.sqrt(np.clip(w, 0.0, None))


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
        self._horizontal = SmoothedGaussMarkov(p.horizontal_sigma_m, p.horizontal_tau_s, p.position_smoothing_s, rng, 2)
        self._vertical = SmoothedGaussMarkov(p.vertical_sigma_m, p.vertical_tau_s, p.position_smoothing_s, rng)
        self._tilt = SmoothedGaussMarkov(math.radians(p.tilt_sigma_deg), p.tilt_tau_s, p.attitude_smoothing_s, rng, 2)
        self._heading = SmoothedGaussMarkov(math.radians(p.heading_sigma_deg), p.heading_tau_s,
                                            p.attitude_smoothing_s, rng)
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
