"""Flying the vehicle's stored mission in ArduPilot's AUTO, followed by MISSION_CURRENT and
MISSION_ITEM_REACHED.

AUTO is then the mode the link flies in, so another mode is a takeover (see
:mod:`layerpilot.link.control`). Uploading the mission is :mod:`layerpilot.link.mission_transfer`'s.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.commands import Commands
from layerpilot.link.control import Control
from layerpilot.link.errors import LinkError
from layerpilot.link.sync import LinkSync
from layerpilot.link.vehicle_state import VehicleState


def fly_mission(state: VehicleState, commands: Commands, control: Control, sync: LinkSync, last: int,
                timeout: float, progress: Callable[[str, int], None] | None = None) -> None:
    """Fly the stored mission in AUTO until item ``last`` is reached; see :meth:`FlightLink.fly_mission`."""
    state.require_link()
    auto = modes.MISSION_MODE.get(state.flavour)
    if auto is None:
        raise LinkError(f"fly_mission: stored missions are flown in ArduPilot's AUTO only (this is {state.flavour})")
    if not state.armed:
        raise LinkError("fly_mission: the vehicle is not armed (take off first: ArduCopter refuses AUTO on "
                        "the ground unless the mission starts with a takeoff)")
    upsets = len(control.upsets)
    with sync.cond:
        control.setpoint, control.stream_hold, control.abandoned = None, False, ""
        control.in_control, control.paused, control.auto = True, False, True
        state.mission_current, state.reached = -1, []
    commands.send(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_MISSION_CURRENT, 1e6)
    try:
        commands.set_mode(auto)
    except LinkError:
        with sync.cond:
            control.in_control = control.auto = False
        raise
    deadline = time.monotonic() + timeout
    told = (-1, 0)
    while True:
        sync.check_interrupted("flying the mission")
        control.check_upsets(upsets, "flying the mission")
        with sync.cond:
            current, reached = state.mission_current, list(state.reached)
        if progress is not None:  # in the vehicle's order: an item reached, then the next one current
            for seq in reached[told[1]:]:
                progress("reached", seq)
            if current != told[0] and current >= 0:
                progress("current", current)
        told = (current, len(reached))
        if last in reached:
            return
        if time.monotonic() >= deadline:
            raise LinkError(f"mission: item {last} not reached within {timeout:.1f} s (flying item {current}, "
                            f"reached {reached or 'none'})")
        sync.wait(lambda: (state.mission_current, len(state.reached)) != told or len(control.upsets) > upsets,
                  deadline - time.monotonic())
