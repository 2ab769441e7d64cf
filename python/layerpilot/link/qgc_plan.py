"""QGroundControl ``.plan`` files: a planned flight as JSON that QGC opens and MAVLink items for upload.

The format is QGC's plan file version 1 (https://docs.qgroundcontrol.com/master/en/qgc-dev-guide/
file_formats/plan.html): ``fileType: "Plan"``, a ``mission`` whose ``items`` are ``SimpleItem``s
(``command`` 16 NAV_WAYPOINT, ``frame`` 3 altitude relative to home, ``params`` [hold s,
acceptance m, pass radius m, yaw deg or null, lat, lon, alt]), ``plannedHomePosition`` [lat, lon,
alt above mean sea level], and empty ``geoFence`` and ``rallyPoints``.

Waypoints come in the map frame; ``LocalFrame`` places them on the Earth, and their altitude
above home is map z minus home's z (for a mission's map, whose origin is home on the ground,
simply z).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from layerpilot.geodesy import LocalFrame
from layerpilot.link.mission_transfer import GLOBAL, GLOBAL_RELATIVE_ALT, NAV_WAYPOINT, MissionItem

FIRMWARE = {"ardupilot": 3, "px4": 12, "generic": 0}  # MAV_AUTOPILOT, which QGC records as firmwareType
QUADROTOR = 2  # MAV_TYPE
ARDUPILOT, PX4 = 3, 12  # MAV_AUTOPILOT_ARDUPILOTMEGA, MAV_AUTOPILOT_PX4


@dataclass(frozen=True)
class Plan:
    """A mission and the home it was planned from (lat, lon in degrees, alt m above mean sea level)."""

    items: list[MissionItem]
    home: tuple[float, float, float]
    firmware: str = "ardupilot"
    cruise_speed: float = 5.0
    hover_speed: float = 5.0


def plan_from_waypoints(waypoints: np.ndarray, frame: LocalFrame, home: Sequence[float] = (0.0, 0.0, 0.0),
                        *, acceptance: float = 2.0, firmware: str = "ardupilot", speed: float = 5.0) -> Plan:
    """NAV_WAYPOINT items at map-frame ``waypoints`` (n, 3), relative to ``home`` (map frame, on the ground)."""
    wp = np.asarray(waypoints, float).reshape(-1, 3)
    if firmware not in FIRMWARE:
        raise ValueError(f"firmware: expected one of {', '.join(FIRMWARE)}, got {firmware!r}")
    lat, lon, _ = frame.to_geodetic(wp[:, 0], wp[:, 1], wp[:, 2])
    hlat, hlon, halt = frame.to_geodetic(*(float(v) for v in home))
    items = [MissionItem(float(a), float(o), float(z - home[2]), params=(0.0, acceptance, 0.0, math.nan))
             for a, o, z in zip(lat, lon, wp[:, 2])]
    return Plan(items, (float(hlat), float(hlon), float(halt)), firmware, speed, speed)


def plan_json(plan: Plan) -> dict:
    """The ``.plan`` document."""
    items = []
    for i, item in enumerate(plan.items, 1):
        params = [None if math.isnan(p) else p for p in item.params] + [item.lat, item.lon, item.alt]
        items.append({"type": "SimpleItem", "doJumpId": i, "autoContinue": item.autocontinue,
                      "command": item.command, "frame": item.frame, "params": params,
                      "Altitude": item.alt, "AltitudeMode": 1, "AMSLAltAboveTerrain": None})
    return {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "layerpilot",
        "mission": {"version": 2, "firmwareType": FIRMWARE[plan.firmware], "vehicleType": QUADROTOR,
                    "cruiseSpeed": plan.cruise_speed, "hoverSpeed": plan.hover_speed,
                    "globalPlanAltitudeMode": 1, "plannedHomePosition": list(plan.home), "items": items},
        "geoFence": {"version": 2, "circles": [], "polygons": []},
        "rallyPoints": {"version": 2, "points": []},
    }


def write_plan(path: Path, plan: Plan) -> Path:
    Path(path).write_text(json.dumps(plan_json(plan), indent=2) + "\n")
    return Path(path)


def read_plan(path: Path) -> Plan:
    """A ``.plan`` file's SimpleItems (any command and frame) and home; a clear error for anything else."""
    try:
        doc = json.loads(Path(path).read_text())
    except OSError as exc:
        raise FileNotFoundError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON: {exc}") from None
    if not isinstance(doc, dict) or doc.get("fileType") != "Plan" or not isinstance(doc.get("mission"), dict):
        raise ValueError(f"{path}: not a QGroundControl plan (fileType 'Plan' with a mission)")
    mission = doc["mission"]
    firmware = {v: k for k, v in FIRMWARE.items()}.get(mission.get("firmwareType"), "generic")
    try:
        home = tuple(float(v) for v in mission["plannedHomePosition"])
        items = [_item(entry) for entry in mission.get("items", [])]
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: malformed mission: {exc}") from None
    if len(home) != 3:
        raise ValueError(f"{path}: plannedHomePosition must be [lat, lon, alt], got {list(home)}")
    return Plan(items, home, firmware, float(mission.get("cruiseSpeed", 5.0)), float(mission.get("hoverSpeed", 5.0)))


def _item(entry: dict) -> MissionItem:
    if entry.get("type") != "SimpleItem":
        raise ValueError(f"item type {entry.get('type')!r}: only SimpleItem is supported (no complex items)")
    params = [math.nan if p is None else float(p) for p in entry["params"]]
    if len(params) != 7:
        raise ValueError(f"params must hold 7 values, got {len(params)}")
    return MissionItem(params[4], params[5], params[6], int(entry.get("command", NAV_WAYPOINT)),
                       int(entry.get("frame", GLOBAL_RELATIVE_ALT)), tuple(params[:4]),
                       bool(entry.get("autoContinue", True)))


def mission_items(plan: Plan, autopilot: int) -> list[MissionItem]:
    """The items to upload to an autopilot of type ``autopilot`` (HEARTBEAT's MAV_AUTOPILOT).

    ArduPilot keeps home as mission item 0 and takes the plan from item 1 on (what QGC does
    too); PX4 and others get the plan's items as they are.
    """
    if autopilot != ARDUPILOT:
        return list(plan.items)
    lat, lon, alt = plan.home
    return [MissionItem(lat, lon, alt, frame=GLOBAL, params=(0.0, 0.0, 0.0, 0.0)), *plan.items]


def plan_from_mission(downloaded: list[MissionItem], autopilot: int,
                      home: tuple[float, float, float] | None = None) -> Plan:
    """The inverse of :func:`mission_items`: a downloaded mission as a plan (ArduPilot's item 0 is its home;
    other autopilots' home comes from their HOME_POSITION, ``home``)."""
    firmware = {ARDUPILOT: "ardupilot", PX4: "px4"}.get(autopilot, "generic")
    if autopilot == ARDUPILOT:
        if not downloaded:
            raise ValueError("mission: ArduPilot always holds home as item 0; the vehicle sent no items")
        first = downloaded[0]
        return Plan(downloaded[1:], (first.lat, first.lon, first.alt), firmware)
    if home is None:
        raise ValueError("home: needed for a mission from an autopilot other than ArduPilot")
    return Plan(list(downloaded), home, firmware)
