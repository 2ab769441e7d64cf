"""What the simulated autopilot knows about itself, shared by the endpoint's parts.

The clock and the boot, arming, the mode, home and the EKF origin, whether it flies, the
battery and the estimator: every part (modes, setpoints, flight, streams, telemetry) reads
and changes this one object, always under the endpoint's lock.
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.sim.battery import Battery
from layerpilot.sim.endpoint_config import EndpointConfig
from layerpilot.sim.estimate import Estimator, VehiclePose
from layerpilot.sim.vehicle import Multicopter


class AutopilotState:
    """The autopilot's state and the small rules every part applies to it (readiness, refusals, disarming)."""

    def __init__(self, vehicle: Multicopter, config: EndpointConfig, mavlink: mav.MAVLink) -> None:
        self.vehicle = vehicle
        self.config = config
        self.mav = mavlink                 # the encoder: everything sent goes to every peer
        self.flavour = config.flavour
        self.time = 0.0                    # the mission clock
        self.boots = 1
        self.boot_at = 0.0                 # mission time of the last boot: time_boot_ms counts from here
        self.home = vehicle.position.copy()
        # the EKF origin: the first good position, on the ground at home (ArduCopter and PX4 alike)
        self.ekf_origin = np.array([self.home[0], self.home[1], vehicle.ground_z], dtype=float)
        self.armed = False
        self.mode = self.first_mode
        self.airborne = False
        self.ground_time = 0.0             # armed on the ground this long: auto-disarm after auto_disarm_s
        self.rtl_phase = ""                # RTL (and AUTO's RTL/LAND items): "climb", "return", "land" or ""
        self.velocity_deadline: float | None = None
        self.setpoint_times: list[float] = []
        self.battery = Battery(config.battery)
        self.battery_failsafe = False      # ArduCopter acts on the low-battery failsafe once per boot
        self.estimator = Estimator(config.sensors, config.seed)
        self.exact_pose = config.sensors.exact_pose

    @property
    def first_mode(self) -> str:
        return "STABILIZE" if self.flavour == modes.ARDUPILOT else "POSCTL"

    @property
    def uptime(self) -> float:
        """Seconds since the autopilot booted (its time_boot_ms)."""
        return self.time - self.boot_at

    def boot_ms(self) -> int:
        return int(self.uptime * 1000) & 0xFFFFFFFF

    def has_fix(self) -> bool:
        return self.uptime >= 0.5 * self.config.prearm_delay_s

    def prearm_ok(self) -> bool:
        return self.uptime >= self.config.prearm_delay_s

    @property
    def refused(self) -> int:
        """The result code this autopilot uses for "not now" (ArduPilot FAILED, PX4 TEMPORARILY_REJECTED)."""
        return mav.MAV_RESULT_FAILED if self.flavour == modes.ARDUPILOT else mav.MAV_RESULT_TEMPORARILY_REJECTED

    def text(self, severity: int, text: str) -> None:
        self.mav.statustext_send(severity, text[:50].encode())

    def pose(self) -> VehiclePose:
        roll, pitch = self.vehicle.roll_pitch
        return VehiclePose(self.time, self.vehicle.position.copy(), self.vehicle.velocity.copy(),
                           roll, pitch, self.vehicle.yaw)

    def reported_pose(self) -> VehiclePose:
        return self.pose() if self.exact_pose else self.estimator.report(self.pose())

    def true_target(self, position: tuple) -> tuple:
        """Where the vehicle goes for a target in its estimated frame: the target minus the EKF's drift."""
        if self.exact_pose:
            return position
        return tuple(float(c) for c in np.subtract(position, self.estimator.errors.current.drift))

    def set_disarmed(self, reason: str) -> None:
        if self.armed and reason:
            self.text(mav.MAV_SEVERITY_INFO, reason)
        self.armed, self.vehicle.motors_on = False, False
        self.airborne = False
        self.rtl_phase = ""

    def change_speed(self, speed: float) -> int:
        """DO_CHANGE_SPEED: a horizontal cruise speed up to the airframe's limit; -1 no change, -2 default."""
        if speed == -1.0:
            return mav.MAV_RESULT_ACCEPTED
        if speed == -2.0:
            self.vehicle.cruise_speed = None
            return mav.MAV_RESULT_ACCEPTED
        if not math.isfinite(speed) or speed <= 0.0:
            return mav.MAV_RESULT_DENIED
        self.vehicle.cruise_speed = min(float(speed), self.vehicle.limits.max_speed_h)
        return mav.MAV_RESULT_ACCEPTED

    def reboot(self) -> None:
        """A new boot: disarmed on the ground at home in the first mode, every per-boot memory forgotten."""
        self.boots += 1
        self.boot_at = self.time
        v = self.vehicle
        v.position[:] = (self.home[0], self.home[1], v.ground_z)
        v.velocity[:], v.acceleration[:], v.yaw_rate = 0.0, 0.0, 0.0
        self.set_disarmed("")
        v.hold()
        self.mode = self.first_mode
        self.velocity_deadline, self.setpoint_times = None, []
        self.battery_failsafe = False
