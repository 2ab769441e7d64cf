"""Which messages the simulated autopilot sends and when: message intervals, ArduPilot's data streams,
one-off requests, and the scheduler that sends what is due each step (times are mission seconds)."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.sim.autopilot_state import AutopilotState
from layerpilot.sim.telemetry_sender import TelemetrySender

# Telemetry intervals (mission seconds): what PX4 streams unasked, and the rates of the ArduPilot
# flavour's SRx_ streams for a GCS link - which, like ArduCopter's (SRx_ defaults 0), it sends only
# once asked (SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM); unasked it sends HEARTBEAT alone.
DEFAULT_INTERVALS = {
    mav.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    mav.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: 0.2,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.1,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.1,
    mav.MAVLINK_MSG_ID_ATTITUDE: 0.1,
    mav.MAVLINK_MSG_ID_HOME_POSITION: 5.0,
    mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: 5.0,
    mav.MAVLINK_MSG_ID_EKF_STATUS_REPORT: 1.0,   # ArduPilot only (its EXTRA3 stream); PX4 has none
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,      # ArduPilot's EXTRA3 stream
    mav.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,         # uptime (time_boot_ms); no GPS clock (0)
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,     # ArduPilot's EXTENDED_STATUS stream (and at once on a new item)
}
# ArduPilot's REQUEST_DATA_STREAM groups (its SRx_ parameters) of the messages above
DATA_STREAMS = {
    mav.MAV_DATA_STREAM_EXTENDED_STATUS: (mav.MAVLINK_MSG_ID_SYS_STATUS, mav.MAVLINK_MSG_ID_GPS_RAW_INT,
                                          mav.MAVLINK_MSG_ID_MISSION_CURRENT),
    mav.MAV_DATA_STREAM_POSITION: (mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    mav.MAV_DATA_STREAM_EXTRA1: (mav.MAVLINK_MSG_ID_ATTITUDE,),
    mav.MAV_DATA_STREAM_EXTRA3: (mav.MAVLINK_MSG_ID_SYSTEM_TIME, mav.MAVLINK_MSG_ID_EKF_STATUS_REPORT,
                                 mav.MAVLINK_MSG_ID_BATTERY_STATUS),
}
# without a position estimate (no GPS fix yet) there is no origin, no home and no position to send
NEEDS_FIX = frozenset({mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                       mav.MAVLINK_MSG_ID_HOME_POSITION, mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN})


class Streams:
    """The interval of every message (inf: off) and when it is next due; :meth:`send_due` runs each step."""

    def __init__(self, state: AutopilotState, telemetry: TelemetrySender) -> None:
        self._s = state
        self._telemetry = telemetry
        self.reset()

    def reset(self) -> None:
        """Each boot: intervals at their defaults, everything due now, home not announced yet."""
        self.intervals = self._default_intervals()
        self._next_send = {msg_id: self._s.time for msg_id in self.intervals}
        self._home_announced = False  # HOME_POSITION and GPS_GLOBAL_ORIGIN sent once when set, each boot

    def _default_intervals(self) -> dict[int, float]:
        """PX4 streams its set unasked; ArduCopter only HEARTBEAT until a stream is asked for."""
        if self._s.flavour == modes.PX4:
            return dict(DEFAULT_INTERVALS)
        return {msg_id: interval if msg_id == mav.MAVLINK_MSG_ID_HEARTBEAT else math.inf
                for msg_id, interval in DEFAULT_INTERVALS.items()}

    def set_interval(self, msg_id: int, interval_us: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL: -1 off, 0 the default, else microseconds."""
        if msg_id not in DEFAULT_INTERVALS:
            return mav.MAV_RESULT_FAILED
        if interval_us < 0:
            self.intervals[msg_id] = math.inf
        elif interval_us == 0:
            self.intervals[msg_id] = self._default_intervals()[msg_id]
        else:
            self.intervals[msg_id] = interval_us * 1e-6
        self._next_send[msg_id] = self._s.time
        return mav.MAV_RESULT_ACCEPTED

    def request_data_stream(self, stream: int, rate_hz: float) -> None:
        """ArduPilot's REQUEST_DATA_STREAM: a group (or all, MAV_DATA_STREAM_ALL) at ``rate_hz``, 0 stops it."""
        groups = DATA_STREAMS.values() if stream == mav.MAV_DATA_STREAM_ALL else [DATA_STREAMS.get(stream, ())]
        for msg_id in (m for group in groups for m in group):
            self.intervals[msg_id] = 1.0 / rate_hz if rate_hz > 0 else math.inf
            self._next_send[msg_id] = self._s.time

    def send_now(self, msg_id: int) -> int:
        """MAV_CMD_REQUEST_MESSAGE (and GET_HOME_POSITION)."""
        if msg_id not in DEFAULT_INTERVALS:
            return mav.MAV_RESULT_UNSUPPORTED
        self.send(msg_id)
        return mav.MAV_RESULT_ACCEPTED

    def send_due(self) -> None:
        s = self._s
        if not self._home_announced and s.has_fix():  # as ArduCopter when it sets home and the EKF origin
            self._home_announced = True
            self.send(mav.MAVLINK_MSG_ID_HOME_POSITION)
            self.send(mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        for msg_id, interval in self.intervals.items():
            if math.isfinite(interval) and s.time + 1e-9 >= self._next_send[msg_id] and self.send(msg_id):
                self._next_send[msg_id] = max(self._next_send[msg_id] + interval, s.time + 0.5 * interval)

    def send(self, msg_id: int) -> bool:
        """Send message ``msg_id`` now; False when there is nothing to say yet (no position estimate)."""
        if msg_id in NEEDS_FIX and not self._s.has_fix():
            return False  # like an EKF without GPS
        if msg_id == mav.MAVLINK_MSG_ID_EKF_STATUS_REPORT and self._s.flavour != modes.ARDUPILOT:
            return True   # an ArduPilot message; PX4 reports its estimator otherwise
        getattr(self._telemetry, mav.mavlink_map[msg_id].msgname.lower())()
        return True
