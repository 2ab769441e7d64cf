"""Simulated multicopter: point-mass dynamics with speed, acceleration and yaw-rate limits.

A position controller flies toward the current setpoint (or holds a velocity
setpoint). All state is in the map frame (ENU metres, z up, yaw counter-clockwise
from east); the model is a pure function of the sequence of ``step(dt)`` calls,
so it is deterministic at any speed of the mission clock. Altitude stays where
it is unless a setpoint names a new one ("constant altitude by default").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from layerpilot.config import check_range

GRAVITY = 9.80665
BRAKING = 0.8  # fraction of max_accel planned for braking, the rest is margin for the controller


@dataclass(frozen=True)
class VehicleLimits:
    """Flight envelope; speeds in m/s, acceleration in m/s^2, yaw rate in deg/s."""

    max_speed_h: float = 10.0
    max_speed_up: float = 3.0
    max_speed_down: float = 2.0
    max_accel: float = 4.0
    max_yaw_rate_deg: float = 90.0
    position_gain: float = 1.0   # 1/s: commanded speed per metre of position error
    yaw_gain: float = 2.0        # 1/s

    def __post_init__(self) -> None:
        for name in ("max_speed_h", "max_speed_up", "max_speed_down", "max_accel", "max_yaw_rate_deg",
                     "position_gain", "yaw_gain"):
            check_range(name, getattr(self, name), 1e-6, None)


@dataclass
class _Target:
    position: np.ndarray | None = None   # ENU metres
    velocity: np.ndarray | None = None   # ENU m/s, used when position is None
    yaw: float | None = None             # ENU radians
    yaw_rate: float | None = None        # rad/s, used when yaw is None


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@dataclass
class Multicopter:
    """The vehicle's state and controller. ``motors_on`` False keeps it sitting on the ground."""

    limits: VehicleLimits = field(default_factory=VehicleLimits)
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0
    ground_z: float = 0.0
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw_rate: float = 0.0
    motors_on: bool = False
    cruise_speed: float | None = None  # m/s horizontal, set by DO_CHANGE_SPEED; None = max_speed_h

    def __post_init__(self) -> None:
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3).copy()
        if not np.all(np.isfinite(self.position)):
            raise ValueError(f"position: must be 3 finite numbers, got {self.position}")
        self.position[2] = max(self.position[2], self.ground_z)
        self._target = _Target()

    # --- setpoints -------------------------------------------------------------------
    def set_position_target(self, x: float | None = None, y: float | None = None, z: float | None = None,
                            yaw: float | None = None) -> None:
        """Fly to (x, y, z); an omitted coordinate keeps the current target's (or current position's)."""
        base = self._target.position if self._target.position is not None else self.position
        target = np.array([base[0] if x is None else x, base[1] if y is None else y,
                           base[2] if z is None else z], dtype=np.float64)
        if not np.all(np.isfinite(target)):
            raise ValueError(f"position target: must be finite, got {target}")
        target[2] = max(target[2], self.ground_z)
        self._target.position, self._target.velocity = target, None
        self._set_yaw(yaw, None)

    def set_velocity_target(self, vx: float, vy: float, vz: float, yaw: float | None = None) -> None:
        self._target.position, self._target.velocity = None, np.array([vx, vy, vz], dtype=np.float64)
        self._set_yaw(yaw, None)

    def set_yaw_target(self, yaw: float | None = None, yaw_rate: float | None = None) -> None:
        self._set_yaw(yaw, yaw_rate)

    def _set_yaw(self, yaw: float | None, yaw_rate: float | None) -> None:
        self._target.yaw, self._target.yaw_rate = yaw, (None if yaw is not None else yaw_rate)

    def hold(self) -> None:
        """Brake and hold at the stopping point (where the acceleration limit lets it stop), like a loiter."""
        speed = float(np.linalg.norm(self.velocity))
        stop = self.position + self.velocity * speed / (2.0 * self.limits.max_accel * BRAKING)
        stop[2] = max(stop[2], self.ground_z)
        self._target = _Target(position=stop)

    def shift_target(self, delta: np.ndarray) -> None:
        """Move the position target by ``delta`` (an autopilot following its drifting estimate); none, no change."""
        if self._target.position is not None:
            target = self._target.position + delta
            target[2] = max(target[2], self.ground_z)
            self._target.position = target

    @property
    def position_target(self) -> np.ndarray | None:
        return None if self._target.position is None else self._target.position.copy()

    @property
    def on_ground(self) -> bool:
        return self.position[2] <= self.ground_z + 0.05 and self.velocity[2] <= 0.05

    @property
    def roll_pitch(self) -> tuple[float, float]:
        """Tilt (roll right-wing-down, pitch nose-up, radians) that produces the current acceleration."""
        ax, ay = self.acceleration[0], self.acceleration[1]
        forward = ax * math.cos(self.yaw) + ay * math.sin(self.yaw)
        left = -ax * math.sin(self.yaw) + ay * math.cos(self.yaw)
        return math.atan2(-left, GRAVITY), math.atan2(-forward, GRAVITY)

    # --- dynamics --------------------------------------------------------------------
    def step(self, dt: float) -> None:
        """Advance ``dt`` seconds of mission time."""
        if not dt > 0.0:
            raise ValueError(f"dt: must be > 0, got {dt}")
        lim = self.limits
        if not self.motors_on and self.on_ground:
            self.velocity[:] = 0.0
            self.acceleration[:] = 0.0
            self.yaw_rate = 0.0
            self.position[2] = self.ground_z
            return
        desired = self._desired_velocity() if self.motors_on else np.array([0.0, 0.0, -lim.max_speed_down])
        change = desired - self.velocity
        max_change = lim.max_accel * dt
        norm = float(np.linalg.norm(change))
        if norm > max_change:
            change *= max_change / norm
        self.acceleration = change / dt
        old = self.velocity.copy()
        self.velocity = self.velocity + change
        self.position = self.position + 0.5 * (old + self.velocity) * dt
        if self.position[2] < self.ground_z:
            self.position[2] = self.ground_z
            self.velocity[2] = max(self.velocity[2], 0.0)
        self._step_yaw(dt)

    def _desired_velocity(self) -> np.ndarray:
        lim, target = self.limits, self._target
        if target.position is None:
            desired = target.velocity.copy() if target.velocity is not None else np.zeros(3)
        else:
            error = target.position - self.position
            desired = lim.position_gain * error
            # never faster than the speed from which the acceleration limit can still stop at the target
            for axes in (slice(0, 2), slice(2, 3)):
                dist = float(np.linalg.norm(error[axes]))
                speed = float(np.linalg.norm(desired[axes]))
                stop_speed = math.sqrt(2.0 * lim.max_accel * BRAKING * dist)
                if speed > stop_speed:
                    desired[axes] *= stop_speed / speed
        horizontal = float(np.hypot(desired[0], desired[1]))
        top = lim.max_speed_h if self.cruise_speed is None else min(self.cruise_speed, lim.max_speed_h)
        if horizontal > top:
            desired[:2] *= top / horizontal
        desired[2] = min(max(desired[2], -lim.max_speed_down), lim.max_speed_up)
        return desired

    def _step_yaw(self, dt: float) -> None:
        lim = self.limits
        max_rate = math.radians(lim.max_yaw_rate_deg)
        if self._target.yaw is not None:
            rate = lim.yaw_gain * _wrap(self._target.yaw - self.yaw)
            # stop exactly on the target instead of oscillating around it
            rate = max(-abs(_wrap(self._target.yaw - self.yaw)) / dt,
                       min(abs(_wrap(self._target.yaw - self.yaw)) / dt, rate))
        else:
            rate = self._target.yaw_rate or 0.0
        self.yaw_rate = min(max(rate, -max_rate), max_rate)
        self.yaw = _wrap(self.yaw + self.yaw_rate * dt)
