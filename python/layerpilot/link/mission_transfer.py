"""MAVLink missions: the item type, and upload/download by the mission protocol (the GCS side).

Upload: MISSION_COUNT -> the vehicle asks for each item (MISSION_REQUEST_INT, or the legacy
MISSION_REQUEST) -> MISSION_ITEM_INT -> the vehicle's MISSION_ACK. Download:
MISSION_REQUEST_LIST -> MISSION_COUNT -> MISSION_REQUEST_INT / MISSION_ITEM_INT per item ->
our MISSION_ACK. See https://mavlink.io/en/services/mission.html.

Every wait for the vehicle is bounded by ``timeout`` seconds; on silence the last message is
sent again, ``retries`` times, and then :class:`MissionTransferError` says what was awaited
from whom. A MISSION_ACK with an error ends the upload with the vehicle's reason.

``conn`` is a pymavlink connection (``link.connection.open_connection``): ``conn.mav`` sends,
``conn.recv_match`` receives. The vehicle side is ``sim.mission_store``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.geodesy import LocalFrame

NAV_WAYPOINT = mav.MAV_CMD_NAV_WAYPOINT  # 16
LAND = mav.MAV_CMD_NAV_LAND  # 21: where it is or at its place, down to the ground, then disarmed
RTL = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH  # 20: home, whatever its lat/lon say
GLOBAL_RELATIVE_ALT = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT  # 3: altitude above home
GLOBAL = mav.MAV_FRAME_GLOBAL  # 0: altitude above mean sea level (ArduPilot's home item)
RELATIVE_FRAMES = (GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)


class MissionTransferError(RuntimeError):
    """The vehicle did not answer, or refused the mission; the message says which and why."""


@dataclass(frozen=True)
class MissionItem:
    """One mission item as MISSION_ITEM_INT carries it (x/y as degrees here, 1e-7 degrees on the wire).

    ``params``: param1..param4; for NAV_WAYPOINT hold time (s), acceptance radius (m), pass radius
    (m), yaw (deg; NaN: the autopilot's own heading rule).
    """

    lat: float
    lon: float
    alt: float
    command: int = NAV_WAYPOINT
    frame: int = GLOBAL_RELATIVE_ALT
    params: tuple[float, float, float, float] = (0.0, 0.0, 0.0, math.nan)
    autocontinue: bool = True

    def __post_init__(self) -> None:
        if not (-90.0 <= self.lat <= 90.0 and -180.0 <= self.lon <= 180.0 and math.isfinite(self.alt)):
            raise ValueError(f"mission item: lat {self.lat}, lon {self.lon}, alt {self.alt} is not a place")
        if len(self.params) != 4:
            raise ValueError(f"mission item: params holds param1..param4, got {len(self.params)} values")

    def send(self, mavlink: mav.MAVLink, seq: int, target: tuple[int, int]) -> None:
        """Send as MISSION_ITEM_INT number ``seq`` to ``target`` (system, component)."""
        mavlink.mission_item_int_send(*target, seq, self.frame, self.command, 0, int(self.autocontinue),
                                      *self.params, int(round(self.lat * 1e7)), int(round(self.lon * 1e7)),
                                      float(self.alt), mav.MAV_MISSION_TYPE_MISSION)

    @property
    def flies(self) -> bool:
        """Whether the vehicle flies somewhere for this item: a NAV command other than RTL (whose place is
        home, whatever the item says); DO_* and CONDITION_* items change settings where the vehicle is."""
        return self.command <= mav.MAV_CMD_NAV_LAST and self.command != RTL

    def place(self, frame: LocalFrame, home_z: float, here: np.ndarray | None = None) -> np.ndarray:
        """The item's point in the map frame ``frame`` (x, y, z metres); ``home_z``: home's z there, which
        the altitude is relative to in the GLOBAL_RELATIVE_ALT frames (GLOBAL: above mean sea level).
        Lat and lon both 0 mean where the vehicle is (ArduPilot's rule): ``here``'s x, y when given."""
        x, y, _ = frame.from_geodetic(self.lat, self.lon, 0.0)
        if here is not None and self.lat == 0.0 and self.lon == 0.0:
            x, y = here[0], here[1]
        z = home_z + self.alt if self.frame in RELATIVE_FRAMES else self.alt - frame.alt
        return np.array([float(x), float(y), float(z)])

    @classmethod
    def from_message(cls, msg) -> "MissionItem":
        """From a received MISSION_ITEM_INT."""
        return cls(msg.x * 1e-7, msg.y * 1e-7, float(msg.z), int(msg.command), int(msg.frame),
                   (float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4)),
                   bool(msg.autocontinue))


def result_name(result: int) -> str:
    entry = mav.enums["MAV_MISSION_RESULT"].get(result)
    return entry.name if entry is not None else f"result {result}"


def upload_mission(conn, items: Sequence[MissionItem], target: tuple[int, int], *, timeout: float = 1.5,
                   retries: int = 3, progress: Callable[[int, int], None] | None = None) -> None:
    """Upload ``items`` to ``target`` (system, component); returns once the vehicle accepted them."""
    n = len(items)
    last_sent: Callable[[], None] = lambda: conn.mav.mission_count_send(*target, n, mav.MAV_MISSION_TYPE_MISSION)
    last_sent()
    awaiting = "MISSION_REQUEST_INT for item 0" if n else "MISSION_ACK for an empty mission"
    asked: set[int] = set()
    misses = 0
    while True:
        msg = _receive(conn, ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"), target, timeout)
        if msg is None:
            misses += 1
            if misses > retries:
                raise MissionTransferError(f"upload: no {awaiting} from system {target[0]} after {retries + 1} "
                                           f"tries of {timeout:g} s (is the vehicle connected and answering?)")
            last_sent()
            continue
        if getattr(msg, "mission_type", 0) != mav.MAV_MISSION_TYPE_MISSION:
            continue
        misses = 0
        if msg.get_type() == "MISSION_ACK":
            if msg.type != mav.MAV_MISSION_ACCEPTED:
                raise MissionTransferError(f"upload: the vehicle refused the mission: {result_name(msg.type)}"
                                           + (f" (at item {max(asked)})" if asked else ""))
            if len(asked) < n:
                raise MissionTransferError(f"upload: the vehicle accepted after asking for {len(asked)} of {n} items")
            return
        seq = msg.seq
        if not 0 <= seq < n:
            raise MissionTransferError(f"upload: the vehicle asked for item {seq}, the mission has {n}")
        last_sent = (lambda s=seq: items[s].send(conn.mav, s, target))
        last_sent()
        asked.add(seq)
        if progress is not None:
            progress(len(asked), n)
        awaiting = f"MISSION_REQUEST_INT for item {seq + 1}" if seq + 1 < n else "MISSION_ACK"


def vehicle_frame(conn, target: tuple[int, int], timeout: float) -> tuple[LocalFrame, float]:
    """The autopilot's local frame on the Earth: a :class:`LocalFrame` at its EKF origin (GPS_GLOBAL_ORIGIN,
    where the flight link's map frame starts) and home's z in it (HOME_POSITION), each asked for with
    REQUEST_MESSAGE once a second until both came, at most ``timeout`` seconds."""
    wanted = {"GPS_GLOBAL_ORIGIN": mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,
              "HOME_POSITION": mav.MAVLINK_MSG_ID_HOME_POSITION}
    got: dict[str, object] = {}
    deadline = time.monotonic() + timeout
    while len(got) < len(wanted):
        left = deadline - time.monotonic()
        if left <= 0:
            missing = " and ".join(k for k in wanted if k not in got)
            raise MissionTransferError(f"no {missing} from system {target[0]} within {timeout:g} s (needed to "
                                       "place the mission in the vehicle's frame)")
        for name, msg_id in wanted.items():
            if name not in got:
                conn.mav.command_long_send(*target, mav.MAV_CMD_REQUEST_MESSAGE, 0, msg_id, 0, 0, 0, 0, 0, 0)
        msg = _receive(conn, tuple(k for k in wanted if k not in got), target, min(1.0, left))
        if msg is not None:
            got[msg.get_type()] = msg
    origin, home = got["GPS_GLOBAL_ORIGIN"], got["HOME_POSITION"]
    frame = LocalFrame(origin.latitude * 1e-7, origin.longitude * 1e-7, origin.altitude * 1e-3)
    return frame, (home.altitude - origin.altitude) * 1e-3


def download_mission(conn, target: tuple[int, int], *, timeout: float = 1.5, retries: int = 3) -> list[MissionItem]:
    """The mission stored on ``target`` (system, component), item by item."""
    request_list = lambda: conn.mav.mission_request_list_send(*target, mav.MAV_MISSION_TYPE_MISSION)
    count = _ask(conn, request_list, ("MISSION_COUNT",), target, timeout, retries, "MISSION_COUNT",
                 lambda m: True).count
    items = []
    for seq in range(count):
        request = (lambda s=seq: conn.mav.mission_request_int_send(*target, s, mav.MAV_MISSION_TYPE_MISSION))
        msg = _ask(conn, request, ("MISSION_ITEM_INT",), target, timeout, retries, f"MISSION_ITEM_INT {seq}",
                   lambda m, s=seq: m.seq == s)
        items.append(MissionItem.from_message(msg))
    conn.mav.mission_ack_send(*target, mav.MAV_MISSION_ACCEPTED, mav.MAV_MISSION_TYPE_MISSION)
    return items


def _ask(conn, send: Callable[[], None], types: tuple[str, ...], target: tuple[int, int], timeout: float,
         retries: int, what: str, accept: Callable) -> object:
    for _ in range(retries + 1):
        send()
        end = time.monotonic() + timeout
        while (left := end - time.monotonic()) > 0:
            msg = _receive(conn, types, target, left)
            if msg is not None and getattr(msg, "mission_type", 0) == mav.MAV_MISSION_TYPE_MISSION and accept(msg):
                return msg
    raise MissionTransferError(f"download: no {what} from system {target[0]} after {retries + 1} tries of "
                               f"{timeout:g} s (is the vehicle connected and answering?)")


def _receive(conn, types: tuple[str, ...], target: tuple[int, int], timeout: float):
    """The next message of ``types`` from ``target``'s system within ``timeout`` s, or None."""
    end = time.monotonic() + timeout
    while (left := end - time.monotonic()) > 0:
        msg = conn.recv_match(type=list(types), blocking=True, timeout=left)
        if msg is not None and msg.get_srcSystem() == target[0]:
            return msg
    return None
