"""ArduCopter's AUTO and PX4's AUTO.MISSION on the endpoint: their checks on entry, and the stored mission's run.

The run itself (item by item) is :class:`~layerpilot.sim.auto_mission.AutoMission`; this part
decides when a run starts, resumes or starts over, and hands the mission's LAND and RTL items to
the endpoint's landing and return. PX4 numbers the mission from item 0 (no home item) and, once the
last item is reached, switches to AUTO.LOITER where the vehicle is.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.mission_transfer import MissionItem
from layerpilot.sim.auto_mission import AutoMission
from layerpilot.sim.autopilot_state import AutopilotState
from layerpilot.sim.landing import Landing
from layerpilot.sim.mission_store import MissionStore


class AutoMode:
    """The stored mission flown in the flavour's mission mode; ``run`` is None until that mode first starts it."""

    def __init__(self, state: AutopilotState, store: MissionStore, landing: Landing) -> None:
        self._s = state
        self._store = store
        self._landing = landing
        self.run: AutoMission | None = None

    def start(self) -> int | None:
        """The checks on entering the mission mode; None when the mission starts (or resumes), else the refusal.

        ArduCopter's: a mission beyond home, and a takeoff item first when armed on the ground. The
        simulated PX4 asks the same (a real PX4 takes off to MIS_TAKEOFF_ALT by itself instead)."""
        s, items = self._s, self._store.items
        first = modes.FIRST_ITEM[s.flavour]
        if len(items) <= first:
            s.text(mav.MAV_SEVERITY_WARNING, "Mode change to AUTO failed: init failed" if first else
                   "Mission rejected: no valid mission available")
            return s.refused
        if s.armed and not s.airborne and items[first].command != mav.MAV_CMD_NAV_TAKEOFF:
            s.text(mav.MAV_SEVERITY_CRITICAL, "Auto: Missing Takeoff Cmd" if first else
                   "Mission rejected: takeoff item required on the ground")
            return s.refused
        if self.run is None or self.run.complete or self.run.items is not items:
            self.run = AutoMission(s.mav, items, s.config.origin, s.home, self._run_item, first)
        if s.armed:
            self.run.resume(s.vehicle)
        return None

    def update(self) -> None:
        """Fly the mission; its LAND and RTL items use the endpoint's landing and return."""
        s = self._s
        v = s.vehicle
        if not s.rtl_phase:
            action = self.run.step(v, s.time)
            if action:
                s.rtl_phase = "climb" if action == "rtl" else "land"
            if self.run.complete and s.flavour == modes.PX4:  # PX4's mission end: AUTO.LOITER, holding there
                s.mode = "LOITER"
            target = v.position_target
            s.airborne = s.airborne or (target is not None and target[2] > v.ground_z + 0.2)
        if s.rtl_phase and s.airborne:
            self._landing.rtl()

    def forget(self) -> None:
        """A reboot: a mission flown afterwards starts again at item 1."""
        self.run = None

    def send_current(self) -> None:
        """MISSION_CURRENT as ArduPilot: the item flown and the mission's state; before any run item 0,
        NOT_STARTED (NO_MISSION without items); the total leaves out ArduPilot's home item."""
        s = self._s
        if self.run is not None and self.run.items is self._store.items:
            self.run.send_current(s.mode == modes.MISSION_MODE[s.flavour])
            return
        total = max(len(self._store.items) - modes.FIRST_ITEM[s.flavour], 0)
        s.mav.mission_current_send(0, total, mav.MISSION_STATE_NOT_STARTED if total else
                                   mav.MISSION_STATE_NO_MISSION, 0)

    def _run_item(self, item: MissionItem) -> None:
        """A DO_* mission item, as its COMMAND_LONG (the mission store takes only DO_CHANGE_SPEED)."""
        if item.command == mav.MAV_CMD_DO_CHANGE_SPEED:
            self._s.change_speed(item.params[1])
