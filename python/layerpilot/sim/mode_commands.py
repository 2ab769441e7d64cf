"""Arming, disarming, mode changes and take-off: accepted or refused as ArduCopter (or PX4) would."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.sim.auto_mode import AutoMode
from layerpilot.sim.autopilot_state import AutopilotState
from layerpilot.sim.setpoints import Setpoints

UNARMABLE = ("RTL", "LAND", "TAKEOFF", "AUTO")  # AUTO: ArduCopter's default AUTO_OPTIONS 0
HOLD_ON_ENTRY = ("GUIDED", "LOITER", "STABILIZE", "POSCTL", "OFFBOARD", "RTL", "LAND")


class ModeCommands:
    """Each method answers one command with its MAV_RESULT (and the autopilot's STATUSTEXT on a refusal)."""

    def __init__(self, state: AutopilotState, auto: AutoMode, setpoints: Setpoints) -> None:
        self._s = state
        self._auto = auto
        self._setpoints = setpoints

    def arm(self, force: bool) -> int:
        s = self._s
        ardupilot = s.flavour == modes.ARDUPILOT
        if s.armed:
            return mav.MAV_RESULT_ACCEPTED
        if not s.prearm_ok() and not force:
            s.text(mav.MAV_SEVERITY_CRITICAL, "PreArm: Need Position Estimate" if ardupilot
                   else "Preflight Fail: No valid position estimate")
            return s.refused
        if s.mode in UNARMABLE:
            s.text(mav.MAV_SEVERITY_CRITICAL, "Arm: Mode not armable" if ardupilot
                   else f"Arming denied: not in {s.mode}")
            return s.refused
        if s.mode == "OFFBOARD" and not self._setpoints.stream_ok():
            s.text(mav.MAV_SEVERITY_CRITICAL, "Arming denied: offboard signal lost")
            return s.refused
        s.armed, s.vehicle.motors_on = True, True
        s.ground_time = 0.0
        s.vehicle.hold()
        s.text(mav.MAV_SEVERITY_INFO, "Arming motors" if ardupilot else "Armed by external command")
        return mav.MAV_RESULT_ACCEPTED

    def disarm(self, force: bool) -> int:
        s = self._s
        if s.airborne and not force:
            s.text(mav.MAV_SEVERITY_CRITICAL, "Disarm: vehicle is flying" if s.flavour == modes.ARDUPILOT
                   else "Disarming denied: not landed")
            return s.refused
        s.set_disarmed("Disarming motors")
        return mav.MAV_RESULT_ACCEPTED

    def set_mode_numbers(self, base_mode: int, custom_mode: int) -> int:
        """A mode as SET_MODE and DO_SET_MODE carry it (base mode flags, the flavour's custom mode)."""
        s = self._s
        if not base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return mav.MAV_RESULT_UNSUPPORTED
        name = modes.mode_name(s.flavour, custom_mode)
        table = modes.COPTER_MODES if s.flavour == modes.ARDUPILOT else modes.PX4_MODES
        if name not in table:
            s.text(mav.MAV_SEVERITY_WARNING, f"Mode change to {name} failed: unsupported")
            return s.refused
        return self.enter_mode(name)

    def enter_mode(self, name: str) -> int:
        s = self._s
        if name == "OFFBOARD" and not self._setpoints.stream_ok():
            s.text(mav.MAV_SEVERITY_WARNING, "Switching to Offboard is currently not available")
            return s.refused
        if name == "TAKEOFF" and not s.armed:
            return s.refused
        if name == s.mode:
            return mav.MAV_RESULT_ACCEPTED
        if name == modes.MISSION_MODE[s.flavour] and (refusal := self._auto.start()) is not None:
            return refusal
        s.mode = name
        s.velocity_deadline = None
        s.rtl_phase = "climb" if name == "RTL" else ""
        if s.armed and name in HOLD_ON_ENTRY:
            s.vehicle.hold()
        return mav.MAV_RESULT_ACCEPTED

    def takeoff(self, param7: float) -> int:
        """NAV_TAKEOFF: ArduCopter in GUIDED to ``param7`` m above home; PX4 to ``param7`` m AMSL (NaN: 2.5 m up)."""
        s = self._s
        if not s.armed or s.airborne:
            return s.refused
        if s.flavour == modes.ARDUPILOT:
            if s.mode != "GUIDED" or not param7 > 0.0:
                return s.refused
            target_z = s.home[2] + param7
        else:
            target_z = s.home[2] + 2.5 if math.isnan(param7) else param7 - s.config.origin.alt
            self.enter_mode("TAKEOFF")
        s.airborne = True
        s.vehicle.set_position_target(z=s.true_target((0.0, 0.0, target_z))[2])  # climbs on its estimate
        return mav.MAV_RESULT_ACCEPTED
