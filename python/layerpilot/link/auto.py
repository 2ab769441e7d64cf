"""Flying the vehicle's stored mission in ArduPilot's AUTO or PX4's AUTO.MISSION, followed by
MISSION_CURRENT and MISSION_ITEM_REACHED.

That mode is then the one the link flies in, so another mode is a takeover (see
:mod:`layerpilot.link.control`); PX4's switch to AUTO.LOITER once the last item is reached is the
mission's end, not a takeover. Uploading the mission is :mod:`layerpilot.link.mission_transfer`'s.
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
    """Fly the stored mission in the flavour's mission mode until item ``last`` is reached; see
    :meth:`FlightLink.fly_mission`."""
    state.require_link()
    auto = modes.MISSION_MODE.get(state.flavour)
    if auto is None:
        raise LinkError(f"fly_mission: no mission mode known for {state.flavour}")
    if not state.armed:
        raise LinkError("fly_mission: the vehicle is not armed (take off first: ArduCopter refuses AUTO on "
                        "the ground unless the mission starts with a takeoff)")
    upsets = len(control.upsets)
    with sync.cond:
        control.setpoint, control.stream_hold, control.abandoned = None, False, ""
        control.in_control, control.paused, control.auto = True, False, True
        state.mission_current, state.reached, state.mission_complete = -1, [], False
    commands.send(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_MISSION_CURRENT, 1e6)
    try:
        commands.set_mode(auto)
    except LinkError:
        with sync.cond:
            control.in_control = control.auto = False
        raise
    deadline = time.monotonic() + timeout
    told = (-1, 0)
    def tell(current: int, reached: list[int]) -> None:  # in the vehicle's order: reached, then the next current
        if progress is not None:
            for seq in reached[told[1]:]:
                progress("reached", seq)
            if current != told[0] and current >= 0 and last not in reached:
                progress("current", current)

    while True:
        sync.check_interrupted("flying the mission")
        with sync.cond:
            current, reached = state.mission_current, list(state.reached)
        if last in reached:  # before the upsets: PX4 leaves AUTO.MISSION for AUTO.LOITER right after it
            tell(current, reached)
            return
        control.check_upsets(upsets, "flying the mission")
        tell(current, reached)
        told = (current, len(reached))
        if time.monotonic() >= deadline:
            raise LinkError(f"mission: item {last} not reached within {timeout:.1f} s (flying item {current}, "
                            f"reached {reached or 'none'})")
        sync.wait(lambda: (state.mission_current, len(state.reached)) != told or len(control.upsets) > upsets,
                  deadline - time.monotonic())
