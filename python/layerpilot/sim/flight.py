"""What the simulated autopilot does by itself every step: failsafes, the modes' own flying, auto-disarm."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.sim.auto_mission import TAKEOFF_REACHED_M
from layerpilot.sim.auto_mode import AutoMode
from layerpilot.sim.autopilot_state import AutopilotState
from layerpilot.sim.landing import Landing
from layerpilot.sim.mode_commands import ModeCommands


class Flight:
    """Runs around the vehicle's motion: :meth:`before_motion` steers, :meth:`after_motion` judges the result."""

    def __init__(self, state: AutopilotState, commands: ModeCommands, auto: AutoMode, landing: Landing) -> None:
        self._s = state
        self._commands = commands
        self._auto = auto
        self._landing = landing

    def before_motion(self) -> None:
        """PX4's offboard loss, the low-battery failsafe, the guided velocity timeout, then the mode's flying."""
        s = self._s
        v = s.vehicle
        if not s.armed:
            return
        if s.mode == "OFFBOARD" and (not s.setpoint_times or
                                     s.time - s.setpoint_times[-1] > s.config.offboard_loss_s):
            s.text(mav.MAV_SEVERITY_CRITICAL, "Failsafe: offboard signal lost, holding")
            s.mode = "LOITER"
            v.hold()
        if s.battery.low and s.airborne and not s.battery_failsafe and s.mode not in ("RTL", "LAND"):
            s.battery_failsafe = True  # BATT_FS_LOW_ACT = RTL, once: a pilot may then take another mode
            s.text(mav.MAV_SEVERITY_CRITICAL, f"Battery 1 is low {s.battery.voltage:.2f}V used "
                                              f"{s.battery.consumed_mah:.0f} mAh")
            self._commands.enter_mode("RTL")
        if s.velocity_deadline is not None and s.time > s.velocity_deadline:
            s.velocity_deadline = None
            v.hold()
        if s.mode == "TAKEOFF":
            target = v.position_target
            if target is not None and abs(v.position[2] - target[2]) < TAKEOFF_REACHED_M:
                s.mode = "LOITER"
        elif s.mode == "RTL" and s.airborne:
            self._landing.rtl()
        elif s.mode == "LAND" and s.airborne:
            self._landing.descend()
        elif s.mode == modes.MISSION_MODE[s.flavour]:
            self._auto.update()

    def after_motion(self, dt: float) -> None:
        """Drain the battery; disarm on touchdown after a landing, or after ``auto_disarm_s`` idle on the ground."""
        s = self._s
        v = s.vehicle
        s.battery.drain(dt, s.armed)
        if not s.armed:
            return
        if s.airborne and v.on_ground and (s.mode == "LAND" or s.rtl_phase == "land"):
            s.set_disarmed("Land complete, disarming")
            return
        if v.on_ground and not (v.position_target is not None and v.position_target[2] > v.ground_z + 0.2):
            s.ground_time += dt
            if s.ground_time >= s.config.auto_disarm_s:
                s.set_disarmed("Disarming: landed" if s.airborne else "Disarming: auto disarm on ground")
        else:
            s.ground_time = 0.0
