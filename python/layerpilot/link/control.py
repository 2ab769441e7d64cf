"""Who flies the vehicle, towards what, and the failsafe and reboot policy that takes it away.

The link flies the vehicle (``in_control``) in GUIDED/OFFBOARD towards a setpoint, or in AUTO
along its stored mission (``auto``). It stops, and records an upset that ends the mission
thread's waits with :class:`~layerpilot.link.errors.ControlLost`, when:

* the mode changes away from the one the link flies in, made by someone else: a pilot takeover
  (``paused`` until that mode is handed back); within ``FAILSAFE_TEXT_S`` of a low-battery
  STATUSTEXT it is the autopilot's battery failsafe instead (kept in ``failsafe``);
* the autopilot reboots (its uptime goes back): the link lets go (``reboots`` counts them);
* the vehicle disarms while the link flies: the link asks for the uptime and judges at the next
  reading (a reboot if it went back, else a disarm, also after ``UPTIME_WAIT_S`` without one).

A lost link (no HEARTBEAT for ``heartbeat_timeout_s``) stops the setpoints; when it returns after
more than ``long_loss_s`` the link commands ``long_loss_action`` (RTL/LAND) and drops the waypoint.
"""

from __future__ import annotations

import threading
import time

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.commands import Commands
from layerpilot.link.config import LinkConfig
from layerpilot.link.errors import ControlLost
from layerpilot.link.sync import LinkSync
from layerpilot.link.vehicle_state import Heartbeat, VehicleState

UPTIME_WAIT_S = 2.0      # a disarm waits at most this long for the uptime reading that tells a reboot
FAILSAFE_TEXT_S = 5.0    # a mode change this soon after a low-battery STATUSTEXT is the autopilot's failsafe

Setpoint = tuple[np.ndarray, float | None, tuple[float, float] | None, bool]  # target, yaw, look_at, face


class Control:
    """The link's hold on the vehicle and the policy that ends it. Fields are guarded by the link's lock."""

    def __init__(self, config: LinkConfig, state: VehicleState, commands: Commands, sync: LinkSync) -> None:
        self.config, self.state, self.commands, self.sync = config, state, commands, sync
        self.in_control = False     # we put the vehicle in GUIDED/OFFBOARD and fly it
        self.auto = False           # ... or in AUTO, flying its stored mission
        self.paused = False         # the pilot took over
        self.setpoint: Setpoint | None = None
        self.stream_hold = False    # PX4: stream the current position (pre-arm, takeoff prep, pause)
        self.abandoned = ""         # why the current waypoint was dropped (long loss, land/RTL requested)
        self.failsafe = ""          # the autopilot's own failsafe took the vehicle (what it said), if it did
        self.upsets: list[tuple[str, str]] = []  # (kind, what happened): takeovers, failsafes, disarms, reboots
        self.reboots = 0
        self.uptimes_before_reboot: list[float] = []  # the autopilot's uptime (s) when each reboot cut it
        self._long_loss_command: int | None = None
        self._disarmed_at: float | None = None  # an unexplained disarm, judged by the next uptime reading
        self._rebooted = False      # the worker re-requests the streams a reboot forgot

    def flying_mode(self) -> str:
        """The mode the link flies in: AUTO for a stored mission, else GUIDED/OFFBOARD."""
        return modes.MISSION_MODE[self.state.flavour] if self.auto else modes.GUIDED_MODE[self.state.flavour]

    def release(self, why: str) -> None:
        """Stop flying the vehicle (the autopilot has it): no setpoint, not in control. Takes the lock."""
        with self.sync.cond:
            self.in_control, self.paused, self.setpoint, self.stream_hold = False, False, None, False
            self.abandoned = why

    # --- what the worker sees ---------------------------------------------------------
    def on_heartbeat(self, beat: Heartbeat) -> list[str]:
        """(lock held) React to a HEARTBEAT: a restored link, a disarm, a takeover or failsafe, a hand-back.
        Returns the reports to make once the lock is released."""
        reports = []
        mode, flying = self.state.mode, self.flying_mode()
        if beat.lost_for is not None:
            reports.append(self._on_restored(beat.lost_for))
        if beat.disarmed and self.in_control:
            self._disarmed_at = time.monotonic()  # a reboot, or a disarm: the next uptime tells (check_disarm)
        elif self.in_control and not self.paused and mode != flying and beat.old_mode == flying:
            if self.auto and self.state.flavour == modes.PX4 and mode == modes.HOLD_MODE[modes.PX4] \
                    and self.state.mission_complete:  # PX4's end of a mission: AUTO.LOITER, not a takeover
                self.in_control = self.auto = False
                reports.append("mission complete: PX4 holds in AUTO.LOITER")
            elif not (beat.restored and self.state.flavour == modes.PX4 and mode == modes.HOLD_MODE[modes.PX4]):
                self.paused = True
                if failsafe := self._battery_failsafe():
                    self.failsafe = failsafe
                    reports.append(failsafe)
                    self.upsets.append(("failsafe", failsafe))
                else:
                    reports.append(f"pilot took over: mode {mode}; paused until {flying} is handed back")
                    self.upsets.append(("takeover", reports[-1]))
        elif self.in_control and self.paused and mode == flying:
            self.paused = False
            reports.append(f"control handed back ({flying}); resuming")
        return reports

    def after_heartbeat(self, beat: Heartbeat) -> None:
        """The worker's sends after a HEARTBEAT (lock released): the uptime after a disarm; after a loss,
        the uptime again, the long-loss action or PX4's re-entry into OFFBOARD."""
        if beat.lost_for is None:
            if beat.disarmed:
                self.commands.ask_uptime()
            return
        self.commands.ask_uptime()
        if self._long_loss_command is not None:
            self.commands.send(self._long_loss_command)
        elif self.state.flavour == modes.PX4 and self.in_control and self.state.mode == modes.HOLD_MODE[modes.PX4]:
            # PX4 fell back to hold while our stream was stopped: the stream is back, re-enter OFFBOARD
            main, sub = modes.PX4_MODES["OFFBOARD"]
            threading.Timer(self.config.offboard_prestream_s, self.commands.send,
                            args=(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub)).start()

    def _battery_failsafe(self) -> str:
        """What the autopilot's battery failsafe said, if the mode change just seen is one (else "")."""
        low = self.state.low_battery
        if low is None or time.monotonic() - low[0] > FAILSAFE_TEXT_S:
            return ""
        remaining = self.state.battery[1]
        left = f", {remaining}% left" if 0 <= remaining <= 100 else ""
        return f"autopilot failsafe: battery ({low[1]}{left}): {self.state.mode}"

    def _on_restored(self, lost_for: float) -> str:
        action = self.config.long_loss_action
        if lost_for > self.config.long_loss_s and action != "none" and self.in_control:
            self.in_control, self.setpoint, self.stream_hold = False, None, False
            self.abandoned = f"the link commanded {action.upper()} after a long link loss"
            self._long_loss_command = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH if action == "rtl" else mav.MAV_CMD_NAV_LAND
            return (f"link restored after {lost_for:.1f} s (> {self.config.long_loss_s:.1f} s): commanding "
                    f"{action.upper()}")
        self._long_loss_command = None
        return f"link restored after {lost_for:.1f} s; resuming"

    def on_reboot(self, uptime_before: float, uptime: float) -> str:
        """(lock held) The autopilot restarted: let go. Returns the report."""
        self.reboots += 1
        self.uptimes_before_reboot.append(uptime_before)
        self._disarmed_at = None
        text = (f"autopilot rebooted: its uptime went back from {uptime_before:.1f} s to {uptime:.1f} s; "
                f"{'ARMED' if self.state.armed else 'disarmed'} in {self.state.mode}"
                + ("; the link let go of the vehicle" if self.in_control else ""))
        self._let_go("reboot", text)
        self._rebooted = True
        return text

    def check(self, now: float) -> None:
        """The worker's periodic checks: a lost link, a disarm to judge, streams a reboot forgot."""
        if self.state.link_ok and self.state.silent(now):
            with self.sync.cond:
                self.state.link_ok = False
                self.state.lost_at = self.state.last_heartbeat
            self.sync.report(f"link lost: no HEARTBEAT for {self.config.heartbeat_timeout_s:.1f} s; "
                             "no new waypoints until it returns")
        self._check_disarm(now)
        if self._rebooted:
            self._rebooted = False
            self.commands.request_streams()  # a rebooted autopilot forgot the message intervals asked of it

    def _check_disarm(self, now: float) -> None:
        """A disarm while the link flies, reported once an uptime reading since did not go back (no
        reboot), or after UPTIME_WAIT_S without one."""
        with self.sync.cond:
            if self._disarmed_at is None or (self.state.uptime_at <= self._disarmed_at
                                             and now - self._disarmed_at < UPTIME_WAIT_S):
                return
            self._disarmed_at = None
            text = f"the vehicle disarmed while the link was flying it (mode {self.state.mode}); waypoint abandoned"
            self._let_go("disarmed", text)
        self.sync.report(text)

    def _let_go(self, kind: str, text: str) -> None:
        """(lock held) Record an upset and stop flying the vehicle."""
        self.in_control, self.paused, self.setpoint, self.stream_hold = False, False, None, False
        self.abandoned = text
        self.upsets.append((kind, text))
        self.sync.cond.notify_all()

    # --- what the mission thread checks -----------------------------------------------
    def check_upsets(self, since: int, doing: str) -> None:
        """:class:`ControlLost` if a takeover, failsafe, disarm or reboot happened after upset number
        ``since`` (a reboot names itself even when the disarm it caused came first)."""
        new = self.upsets[since:]
        if new:
            kind, text = next((u for u in new if u[0] == "reboot"), new[-1])
            raise ControlLost(f"{doing}: {text}", kind)

    def reboot_since(self, since: int) -> str:
        """What a reboot after upset number ``since`` said ("" if none)."""
        return next((text for kind, text in self.upsets[since:] if kind == "reboot"), "")
