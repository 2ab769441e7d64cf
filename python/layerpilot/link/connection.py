"""Open a MAVLink 2 connection by URL (pymavlink) with the ids layerpilot speaks with."""

from __future__ import annotations

import os
import re

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
    the caller): :class:`~layerpilot.link.link.FlightLink` reconnects on its own schedule.
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
