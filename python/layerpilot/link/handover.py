"""Handing the vehicle back to the autopilot: LAND, RTL and the mission's end action.

The link first stops flying the vehicle (no setpoint, not in control), then commands the
autopilot's own behaviour. The end action never raises: a mission that ends because something
went wrong must still be able to say what became of the vehicle.
"""

from __future__ import annotations

import logging
import time

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.commands import Commands
from layerpilot.link.config import LinkConfig
from layerpilot.link.control import Control
from layerpilot.link.errors import LinkError
from layerpilot.link.sync import LinkSync
from layerpilot.link.vehicle_state import VehicleState

END_ACTIONS = {"rtl": "RTL", "land": "LAND", "loiter": "LOITER"}  # mission end action -> the mode it puts


class Handover:
    """LAND, RTL and the end action of one link."""

    def __init__(self, config: LinkConfig, state: VehicleState, commands: Commands, control: Control,
                 sync: LinkSync) -> None:
        self.config, self.state, self.commands, self.control, self.sync = config, state, commands, control, sync

    def land_or_rtl(self, command: int, what: str, wait: bool, timeout: float) -> None:
        """Command NAV_LAND or NAV_RETURN_TO_LAUNCH (``what``: LAND, RTL); with ``wait``, until disarmed.
        A disarmed vehicle is on the ground: LinkError, nothing sent."""
        self.state.require_link()
        if not self.state.armed:
            raise LinkError(f"{what}: the vehicle is disarmed (on the ground, mode {self.state.mode}); nothing sent")
        self.control.release(f"{what} requested")
        self.commands.command(command)
        if wait and not self.sync.wait(lambda: not self.state.armed, timeout):
            raise LinkError(f"{what}: still armed after {timeout:.1f} s")

    def end_mission(self, action: str, timeout: float) -> tuple[bool, str]:
        """See :meth:`FlightLink.end_mission`."""
        what = END_ACTIONS[action]
        state = self.state
        self.sync.interrupted.clear()
        deadline = time.monotonic() + timeout
        if state.flavour is None:
            return self._ended(False, f"{what} not sent: no autopilot heard on {self.config.url}")
        if not state.link_ok:
            return self._ended(False, f"{what} not sent: link lost (no HEARTBEAT for "
                                      f"{time.monotonic() - state.last_heartbeat:.1f} s)")
        if not state.armed:
            return self._ended(True, f"{what} not needed: the vehicle is disarmed (on the ground, mode {state.mode})")
        self.control.release(f"mission end: {what}")
        command, params = {"rtl": (mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, ()), "land": (mav.MAV_CMD_NAV_LAND, ()),
                           "loiter": (mav.MAV_CMD_DO_SET_MODE, self.commands.mode_params(what))}[action]
        upsets = len(self.control.upsets)

        def reboot() -> str:  # what a reboot during this wait said ("" if none): the wait ends at once
            return self.control.reboot_since(upsets)

        result, tries = self.commands.acknowledged_before(command, params, deadline, lambda: bool(reboot()))
        if result is None:
            if reboot():
                return self._ended(False, f"{what} not acknowledged: {reboot()}")
            why = "link lost" if not state.link_ok else f"no COMMAND_ACK after {tries} tries in {timeout:.1f} s"
            return self._ended(False, f"{what} not acknowledged: {why}")
        if result != mav.MAV_RESULT_ACCEPTED:
            return self._ended(False, f"{what} rejected: {modes.result_name(result)}")
        if not self.sync.wait(lambda: state.mode == what or reboot(), max(0.0, deadline - time.monotonic())):
            return self._ended(False, f"{what} accepted (COMMAND_ACK) but the HEARTBEAT still says mode "
                                      f"{state.mode} after {timeout:.1f} s")
        if reboot():
            return self._ended(False, f"{what} accepted, then {reboot()}")
        return self._ended(True, f"{what} acknowledged (COMMAND_ACK accepted, mode {what})")

    def _ended(self, ok: bool, text: str) -> tuple[bool, str]:
        self.sync.report(f"mission end: {text}", logging.INFO if ok else logging.WARNING)
        return ok, text
