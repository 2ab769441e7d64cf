"""Flight mode numbers of ArduCopter and PX4 as they appear in HEARTBEAT.custom_mode."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mav

ARDUPILOT = "ardupilot"
PX4 = "px4"

# ArduCopter custom_mode numbers (the ones the simulator flies).
COPTER_MODES = {"STABILIZE": 0, "AUTO": 3, "GUIDED": 4, "LOITER": 5, "RTL": 6, "LAND": 9}
_COPTER_ALL = {0: "STABILIZE", 1: "ACRO", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL",
               7: "CIRCLE", 9: "LAND", 16: "POSHOLD", 17: "BRAKE", 21: "SMART_RTL"}

# PX4: custom_mode = main_mode << 16 | sub_mode << 24.
PX4_MODES = {"MANUAL": (1, 0), "POSCTL": (3, 0), "TAKEOFF": (4, 2), "LOITER": (4, 3), "MISSION": (4, 4),
             "RTL": (4, 5), "LAND": (4, 6), "OFFBOARD": (6, 0)}

GUIDED_MODE = {ARDUPILOT: "GUIDED", PX4: "OFFBOARD"}
HOLD_MODE = {ARDUPILOT: "LOITER", PX4: "LOITER"}
MISSION_MODE = {ARDUPILOT: "AUTO", PX4: "MISSION"}  # the mode that flies the stored mission (PX4: AUTO.MISSION)
FIRST_ITEM = {ARDUPILOT: 1, PX4: 0}  # the stored mission's first flown item: ArduPilot keeps home as item 0


def px4_custom_mode(main: int, sub: int) -> int:
    return (main << 16) | (sub << 24)


def custom_mode_of(flavour: str, name: str) -> int:
    """custom_mode number of mode ``name``; ValueError naming it when unknown."""
    if flavour == ARDUPILOT:
        for number, mode in _COPTER_ALL.items():
            if mode == name:
                return number
    elif flavour == PX4 and name in PX4_MODES:
        return px4_custom_mode(*PX4_MODES[name])
    raise ValueError(f"mode: unknown {flavour} mode {name!r}")


def mode_name(flavour: str, custom_mode: int) -> str:
    """Readable mode name of a HEARTBEAT custom_mode (``MODE(n)`` when unknown)."""
    if flavour == PX4:
        main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
        for name, (m, s) in PX4_MODES.items():
            if (m, s) == (main, sub) or (m == main and s == 0 and main != 4):
                return name
        return f"MODE({main}.{sub})"
    return _COPTER_ALL.get(custom_mode, f"MODE({custom_mode})")


def flavour_of(autopilot: int) -> str | None:
    """ArduPilot or PX4 from HEARTBEAT.autopilot; None for anything else (GCS, companions)."""
    if autopilot == mav.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return ARDUPILOT
    if autopilot == mav.MAV_AUTOPILOT_PX4:
        return PX4
    return None


def result_name(result: int) -> str:
    """MAV_RESULT number -> its name (``MAV_RESULT_FAILED``)."""
    entry = mav.enums["MAV_RESULT"].get(result)
    return entry.name if entry is not None else f"MAV_RESULT({result})"


def command_name(command: int) -> str:
    entry = mav.enums["MAV_CMD"].get(command)
    return entry.name if entry is not None else f"MAV_CMD({command})"
