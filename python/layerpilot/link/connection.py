"""Open a MAVLink 2 connection by URL (pymavlink) with the ids layerpilot speaks with, and keep one open."""

from __future__ import annotations

import os
import re
import threading
import time
from collections.abc import Callable

_NETWORK = re.compile(r"^(tcp|tcpin|udp|udpin|udpout|udpbcast):([^:]*):(\d+)$")
_SERIAL = re.compile(r"^(?:serial:)?(/dev/[^:]+|COM\d+)(?::(\d+))?$")


def parse_url(url: str, baud: int = 57600) -> tuple[str, int]:
    """``tcp:HOST:PORT``, ``udpin:HOST:PORT``, ``udpout:HOST:PORT`` or a serial device
    (``/dev/ttyUSB0``, ``/dev/ttyACM0:921600``, ``serial:/dev/ttyAMA0:57600``) -> (device, baud)."""
    network = _NETWORK.match(url)
    if network:
        port = int(network.group(3))
        if not 0 <= port <= 65535:
            raise ValueError(f"url: port {port} is out of range (0-65535) in {url!r}")
        if not network.group(2):
            raise ValueError(f"url: no host in {url!r} (e.g. tcp:127.0.0.1:5760)")
        return url, baud
    serial = _SERIAL.match(url)
    if serial:
        return serial.group(1), int(serial.group(2) or baud)
    raise ValueError(f"url: expected tcp:HOST:PORT, udpin:HOST:PORT, udpout:HOST:PORT or a serial device "
                     f"like /dev/ttyUSB0:57600, got {url!r}")


def open_connection(url: str, source_system: int, source_component: int, baud: int = 57600):
    """A pymavlink connection speaking MAVLink 2 with the ardupilotmega dialect (a superset of common).

    One connection attempt, no hidden reconnection inside pymavlink (it would block
    the caller): :class:`MavlinkPort` reconnects on the flight link's schedule.
    """
    from pymavlink import mavutil  # here: parse_url validates configs without loading pymavlink

    device, baud = parse_url(url, baud)
    os.environ["MAVLINK20"] = "1"  # pymavlink picks the wire protocol from the environment
    conn = mavutil.mavlink_connection(device, baud=baud, source_system=source_system,
                                      source_component=source_component, dialect="ardupilotmega",
                                      autoreconnect=False, retries=0)
    conn.WIRE_PROTOCOL_VERSION = "2.0"
    if isinstance(conn, mavutil.mavtcp):
        conn.handle_eof = conn.handle_disconnect = _closed  # raise instead of printing and carrying on
    return conn


def _closed() -> None:
    raise ConnectionError("connection closed by the other end")


RECONNECT_PERIOD_S = 1.0  # while lost, a stream connection (TCP, serial) is reopened this often


class MavlinkPort:
    """The flight link's connection: opened at once, reopened when it fails or (TCP, serial) falls silent.

    Sends from any thread are serialised and dropped while there is no connection (the link's
    failsafes report that); only the link's worker thread receives, opens and reopens.
    """

    def __init__(self, url: str, source_system: int, source_component: int, baud: int) -> None:
        self.url = url
        self._ids = (source_system, source_component)
        self._baud = baud
        self._stream = not url.startswith("udp")  # UDP has no connection to reopen
        self._lock = threading.Lock()
        self._conn = None
        self.error = ""  # why the last attempt to open failed ("Connection refused")
        self._reopen_at = 0.0
        self.open()

    @property
    def is_open(self) -> bool:
        return self._conn is not None

    def open(self) -> None:
        """(Re)open the connection once; on failure :meth:`keep_open` tries again after RECONNECT_PERIOD_S."""
        self._reopen_at = time.monotonic() + RECONNECT_PERIOD_S
        self.close()
        try:
            conn = open_connection(self.url, *self._ids, self._baud)
        except OSError as exc:
            self.error = exc.strerror or str(exc)  # "Connection refused", not "[Errno 111] ..."
            return
        with self._lock:
            self._conn = conn

    def keep_open(self, now: float, silent: bool) -> None:
        """Reopen a closed connection, or a stream connection whose other end is ``silent``, at most once
        per RECONNECT_PERIOD_S."""
        if now >= self._reopen_at and (self._conn is None or (self._stream and silent)):
            self.open()

    def close(self) -> None:
        with self._lock:
            conn, self._conn = self._conn, None
        if conn is not None:
            try:
                conn.close()
            except (OSError, AttributeError):  # pymavlink's TCP close after a failed reconnect has no socket
                pass

    def receive(self, timeout: float):
        """The next message within ``timeout`` seconds, or None; OSError/ConnectionError when the connection
        broke (TCP reset, serial unplugged)."""
        conn = self._conn
        return None if conn is None else conn.recv_match(blocking=True, timeout=timeout)

    def transmit(self, send: Callable) -> None:
        """``send(encoder)`` with the connection's MAVLink encoder; dropped while disconnected."""
        with self._lock:
            if self._conn is None:
                return
            try:
                send(self._conn.mav)
            except OSError:
                pass
