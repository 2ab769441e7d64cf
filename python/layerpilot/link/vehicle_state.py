"""What the autopilot told the flight link: who it is, whether it is heard, armed, in which mode, ready,
where (map frame, ENU), its home, battery, messages, uptime and mission progress.

The worker thread writes it from the received messages, holding the link's lock; the mission
thread reads it. The tracker only records and judges readiness: what the link does about a
change (a takeover, a reboot) is :mod:`layerpilot.link.control`'s.
"""

from __future__ import annotations

import logging
import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.config import LinkConfig
from layerpilot.link.errors import LinkError, LinkLost
from layerpilot.link.frames import attitude_ned_to_enu, ned_to_enu
from layerpilot.link.sync import LinkSync, log
from layerpilot.link.telemetry import Telemetry

POSITION_FRESH_S = 2.0  # a position estimate older than this does not count
# ArduPilot's EKF_STATUS_REPORT flags: a horizontal position (absolute or relative) and not uninitialised
EKF_POSITION = mav.EKF_POS_HORIZ_ABS | mav.EKF_POS_HORIZ_REL
REBOOT_BACKSTEP_S = 1.0  # the autopilot's uptime went back by more than this: it rebooted
LOW_BATTERY_TEXT = re.compile(r"batt\w*\b.*\b(low|critical|failsafe|emergency)|(low|critical|emergency)\b.*batt",
                              re.IGNORECASE)  # ArduPilot's and PX4's low-battery warnings
UPTIME_MESSAGES = ("ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "SYSTEM_TIME")  # time_boot_ms


@dataclass(frozen=True)
class Heartbeat:
    """What one HEARTBEAT of the autopilot changed."""

    old_mode: str
    disarmed: bool            # armed before, not now (or the autopilot rebooted)
    restored: bool            # the first HEARTBEAT since the link was lost (or ever)
    lost_for: float | None    # how long the link had been lost, when this HEARTBEAT ended a loss


class VehicleState:
    """The autopilot's state as the link last heard it. Write methods expect the link's lock held."""

    def __init__(self, config: LinkConfig, clock: Callable[[], float], sync: LinkSync) -> None:
        self.config, self.clock, self.sync = config, clock, sync
        self.flavour: str | None = None
        self.target_system = config.target_system
        self.target_component = config.target_component
        self.last_heartbeat = -math.inf
        self.link_ok = False
        self.lost_at = 0.0
        self.armed = False
        self.mode = ""
        self.prearm_ok = False
        self.unhealthy: list[str] = []
        self.gps_fix = -1
        self.position_at = -math.inf
        self.ekf_flags: int | None = None  # ArduPilot EKF_STATUS_REPORT flags, once one arrived
        self.pose_time = 0.0
        self.boot_time = 0.0
        self.position = np.zeros(3)
        self.velocity = np.zeros(3)
        self.attitude = (0.0, 0.0, 0.0)
        self.home: np.ndarray | None = None
        self.battery = (0.0, -1)
        self.texts: list[str] = []
        self.low_battery: tuple[float, str] | None = None  # (monotonic, text) of the newest low-battery STATUSTEXT
        self.uptime = -math.inf      # the autopilot's newest time_boot_ms (s): a step back is a reboot
        self.uptime_at = -math.inf   # when (monotonic) the newest uptime reading arrived
        self.mission_current = -1    # the autopilot's MISSION_CURRENT.seq, and the items it reached
        self.reached: list[int] = []
        self.mission_complete = False  # MISSION_CURRENT.mission_state says the mission is complete

    # --- receiving --------------------------------------------------------------------
    def identify(self, msg) -> bool:
        """Whether this HEARTBEAT is our autopilot's; the first ArduPilot/PX4 one matching the configured
        target (0: any) becomes the target. Needs no lock (only the worker writes the target)."""
        flavour = modes.flavour_of(msg.autopilot)
        if flavour is None or msg.type in (mav.MAV_TYPE_GCS, mav.MAV_TYPE_ONBOARD_CONTROLLER):
            return False
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.flavour is None:
            if self.config.target_system not in (0, src[0]) or self.config.target_component not in (0, src[1]):
                return False
            self.flavour, self.target_system, self.target_component = flavour, src[0], src[1]
            self.sync.report(f"autopilot: {flavour} (system {src[0]}, component {src[1]}, MAV_TYPE {msg.type})",
                             logging.INFO)
            return True
        return src == (self.target_system, self.target_component)

    def on_heartbeat(self, msg) -> Heartbeat:
        """Record a HEARTBEAT of our autopilot (lock held)."""
        now = time.monotonic()
        self.last_heartbeat = now
        was_armed, self.armed = self.armed, bool(msg.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
        old, self.mode = self.mode, modes.mode_name(self.flavour, msg.custom_mode)
        restored = not self.link_ok
        self.link_ok = True
        return Heartbeat(old, was_armed and not self.armed, restored,
                         now - self.lost_at if restored and self.lost_at else None)

    def is_target(self, msg) -> bool:
        return msg.get_srcSystem() == self.target_system and msg.get_srcComponent() == self.target_component

    def update(self, msg) -> float | None:
        """Record a message of our autopilot other than HEARTBEAT (lock held). Returns the uptime before,
        when this message's uptime went back (the autopilot rebooted: home, position, EKF and pre-arm state
        are forgotten until it tells them again), else None."""
        kind = msg.get_type()
        rebooted_from = None
        if kind in UPTIME_MESSAGES:
            uptime = msg.time_boot_ms / 1000.0
            if uptime < self.uptime - REBOOT_BACKSTEP_S:
                rebooted_from = self.uptime
                self.home, self.position_at, self.ekf_flags, self.prearm_ok = None, -math.inf, None, False
            self.uptime, self.uptime_at = uptime, time.monotonic()
        if kind == "LOCAL_POSITION_NED":
            self.position = np.array(ned_to_enu(msg.x, msg.y, msg.z))
            self.velocity = np.array(ned_to_enu(msg.vx, msg.vy, msg.vz))
            self.position_at, self.pose_time = time.monotonic(), self.clock()
            self.boot_time = msg.time_boot_ms / 1000.0
        elif kind == "ATTITUDE":
            self.attitude = attitude_ned_to_enu(msg.roll, msg.pitch, msg.yaw)
        elif kind == "SYS_STATUS":
            self._on_sys_status(msg)
        elif kind == "EKF_STATUS_REPORT":
            self.ekf_flags = msg.flags
        elif kind == "GPS_RAW_INT":
            self.gps_fix = msg.fix_type
        elif kind == "HOME_POSITION":
            self.home = np.array(ned_to_enu(msg.x, msg.y, msg.z))
        elif kind == "MISSION_CURRENT":
            self.mission_current = msg.seq
            self.mission_complete = getattr(msg, "mission_state", 0) == mav.MISSION_STATE_COMPLETE
        elif kind == "MISSION_ITEM_REACHED":
            self.reached.append(msg.seq)
        elif kind == "STATUSTEXT":
            self.texts = self.texts[-19:] + [msg.text]
            log.info("autopilot: %s", msg.text)
            if LOW_BATTERY_TEXT.search(msg.text):
                self.low_battery = (time.monotonic(), msg.text)
        return rebooted_from

    def _on_sys_status(self, msg) -> None:
        present = msg.onboard_control_sensors_present
        healthy = msg.onboard_control_sensors_health
        self.prearm_ok = bool(healthy & mav.MAV_SYS_STATUS_PREARM_CHECK) or \
            not present & mav.MAV_SYS_STATUS_PREARM_CHECK
        bad = present & msg.onboard_control_sensors_enabled & ~healthy & ~mav.MAV_SYS_STATUS_PREARM_CHECK
        self.unhealthy = [e.name.replace("MAV_SYS_STATUS_", "") for bit, e in
                          mav.enums["MAV_SYS_STATUS_SENSOR"].items() if bit & bad and bit]
        self.battery = (msg.voltage_battery / 1000.0, msg.battery_remaining)

    def silent(self, now: float) -> bool:
        """No HEARTBEAT for longer than the timeout."""
        return now - self.last_heartbeat > self.config.heartbeat_timeout_s

    # --- judging ----------------------------------------------------------------------
    def require_link(self) -> None:
        if not self.link_ok or self.flavour is None:
            raise LinkLost(f"no link to the autopilot on {self.config.url}")

    def home_or_error(self) -> np.ndarray:
        if self.home is None:
            raise LinkError("home position unknown (no HOME_POSITION yet): call wait_ready() first")
        return self.home

    @property
    def position_valid(self) -> bool:
        """The autopilot has a position: a LOCAL_POSITION_NED arrived and, if it reports its EKF
        (ArduPilot's EKF_STATUS_REPORT), the EKF has a horizontal position. Until then the
        position is (0, 0, 0) and means nothing."""
        return self.position_at > -math.inf and self.ekf_position_ok()

    def position_fresh(self) -> bool:
        return time.monotonic() - self.position_at < POSITION_FRESH_S

    def ekf_position_ok(self) -> bool:
        flags = self.ekf_flags
        return flags is None or bool(flags & EKF_POSITION and not flags & mav.EKF_UNINITIALIZED)

    def missing(self) -> list[str]:
        """What still keeps the vehicle from being ready to fly (empty when ready)."""
        out = []
        if not self.link_ok:
            out.append("autopilot HEARTBEAT" + (" (none heard yet)" if self.flavour is None else
                                                f" (none for {time.monotonic() - self.last_heartbeat:.0f} s)"))
        if not self.prearm_ok:
            out.append("pre-arm checks (SYS_STATUS)" + (f": unhealthy {', '.join(self.unhealthy)}"
                                                         if self.unhealthy else ""))
        if self.gps_fix != -1 and self.gps_fix < mav.GPS_FIX_TYPE_3D_FIX:
            out.append(f"GPS 3D fix (fix_type {self.gps_fix})")
        if not self.ekf_position_ok():
            out.append(f"EKF position (EKF_STATUS_REPORT flags 0x{self.ekf_flags:x})")
        if time.monotonic() - self.position_at > POSITION_FRESH_S:
            out.append("position estimate (LOCAL_POSITION_NED)")
        if self.home is None:
            out.append("home position (HOME_POSITION)")
        return out

    def telemetry(self, paused: bool) -> Telemetry:
        """A snapshot (takes the lock); ``paused``: whether the link waits for a pilot to hand back."""
        with self.sync.cond:
            roll, pitch, yaw = self.attitude
            return Telemetry(self.pose_time, self.boot_time, self.position.copy(), self.velocity.copy(),
                             roll, pitch, yaw, self.armed, self.mode, self.flavour or "",
                             self.battery[0], self.battery[1],
                             self.link_ok, time.monotonic() - self.last_heartbeat,
                             None if self.home is None else self.home.copy(), paused)
