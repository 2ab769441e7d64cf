"""The simulated autopilot's side of the MAVLink mission protocol: store a mission, hand it back.

Upload: on MISSION_COUNT it asks for item 0, 1, ... with MISSION_REQUEST_INT and answers
MISSION_ACK once it has them all (an empty count clears the mission at once). A repeated
MISSION_COUNT restarts the transfer; an item out of turn (a resend) is answered by asking
again for the one it waits for, so the GCS's retries heal lost messages. Items it cannot fly
are refused with the MAV_MISSION_RESULT an autopilot would give. Download: MISSION_REQUEST_LIST
gets MISSION_COUNT, each MISSION_REQUEST_INT (or legacy MISSION_REQUEST) its MISSION_ITEM_INT.
MISSION_CLEAR_ALL clears. Only the mission type MISSION is kept (no fence or rally points).
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link.mission_transfer import MissionItem

MESSAGES = frozenset({"MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_REQUEST_LIST", "MISSION_REQUEST_INT",
                      "MISSION_REQUEST", "MISSION_CLEAR_ALL", "MISSION_ACK"})
COMMANDS = frozenset({mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_LAND,
                      mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, mav.MAV_CMD_DO_CHANGE_SPEED})
FRAMES = frozenset({mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_INT,
                    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})


class MissionStore:
    """The vehicle's stored mission and the transfer in progress; ``handle`` takes every mission message."""

    def __init__(self, mavlink: mav.MAVLink) -> None:
        self._mav = mavlink
        self.items: list[MissionItem] = []
        self._incoming: list[MissionItem] | None = None
        self._peer = (0, 0)
        self._count = 0

    def handle(self, msg) -> None:
        kind = msg.get_type()
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "MISSION_ACK":
            return  # the end of a download: nothing to do
        if getattr(msg, "mission_type", mav.MAV_MISSION_TYPE_MISSION) != mav.MAV_MISSION_TYPE_MISSION:
            self._ack(peer, mav.MAV_MISSION_UNSUPPORTED, msg.mission_type)
        elif kind == "MISSION_COUNT":
            self._start_upload(peer, msg.count)
        elif kind == "MISSION_ITEM_INT":
            self._receive_item(peer, msg)
        elif kind == "MISSION_REQUEST_LIST":
            self._mav.mission_count_send(*peer, len(self.items), mav.MAV_MISSION_TYPE_MISSION)
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            if 0 <= msg.seq < len(self.items):
                self.items[msg.seq].send(self._mav, msg.seq, peer)
            else:
                self._ack(peer, mav.MAV_MISSION_INVALID_SEQUENCE)
        elif kind == "MISSION_CLEAR_ALL":
            self.items, self._incoming = [], None
            self._ack(peer, mav.MAV_MISSION_ACCEPTED)

    def _start_upload(self, peer: tuple[int, int], count: int) -> None:
        if count == 0:
            self.items, self._incoming = [], None
            self._ack(peer, mav.MAV_MISSION_ACCEPTED)
            return
        self._incoming, self._peer, self._count = [], peer, count
        self._request(0)

    def _receive_item(self, peer: tuple[int, int], msg) -> None:
        incoming = self._incoming
        if incoming is None or peer != self._peer:
            return  # no upload from this peer in progress: a late resend
        if msg.seq != len(incoming):
            self._request(len(incoming))  # out of turn (a resend crossed our request): ask again
            return
        refusal = _refusal(msg)
        if refusal is not None:
            self._incoming = None
            self._ack(peer, refusal)
            return
        incoming.append(MissionItem.from_message(msg))
        if len(incoming) < self._count:
            self._request(len(incoming))
        else:
            self.items, self._incoming = incoming, None
            self._ack(peer, mav.MAV_MISSION_ACCEPTED)

    def _request(self, seq: int) -> None:
        self._mav.mission_request_int_send(*self._peer, seq, mav.MAV_MISSION_TYPE_MISSION)

    def _ack(self, peer: tuple[int, int], result: int, mission_type: int = mav.MAV_MISSION_TYPE_MISSION) -> None:
        self._mav.mission_ack_send(*peer, result, mission_type)


def _refusal(msg) -> int | None:
    """The MAV_MISSION_RESULT for an item this vehicle cannot fly, or None if it can."""
    if msg.frame not in FRAMES:
        return mav.MAV_MISSION_UNSUPPORTED_FRAME
    if msg.command not in COMMANDS:
        return mav.MAV_MISSION_UNSUPPORTED
    if not -90e7 <= msg.x <= 90e7:
        return mav.MAV_MISSION_INVALID_PARAM5_X
    if not -180e7 <= msg.y <= 180e7:
        return mav.MAV_MISSION_INVALID_PARAM6_Y
    if not math.isfinite(msg.z):
        return mav.MAV_MISSION_INVALID_PARAM7
    return None
