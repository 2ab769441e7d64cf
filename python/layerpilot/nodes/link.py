"""The link node: waypoints from the bus to a MAVLink autopilot, the vehicle's pose back to the bus.

At start it connects, waits until the autopilot is ready, takes control (GUIDED /
OFFBOARD), arms and climbs to ``takeoff_altitude``; then every waypoint becomes a
setpoint and the pose is published at ``pose_rate``. Pose stamps are the autopilot's
clock (time_boot_ms): the simulator stamps its camera frames, and so the clouds and layer
sets, with the same clock, at any speed; in camera-only mode the frames take the pose's stamp.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import zenoh

from layerpilot.bus import keys
from layerpilot.bus.guard import guarded
from layerpilot.bus.messages import State, Waypoint, decode_waypoint, encode_state
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.bus.session import publish
from layerpilot.config import check_range
from layerpilot.link.config import LinkConfig
from layerpilot.link.link import FlightLink, LinkError
from layerpilot.nodes.runner import wait_for_stop

_log = logging.getLogger("layerpilot.link")


@dataclass(frozen=True)
class LinkNodeConfig:
    """The ``[link]`` table of a mission file: the flight link's settings plus the node's own."""

    link: LinkConfig = field(default_factory=LinkConfig)
    takeoff_altitude: float = 30.0  # m above home
    pose_rate: float = 10.0  # Hz

    def __post_init__(self) -> None:
        check_range("link.takeoff_altitude", self.takeoff_altitude, 1.0, 500.0)
        check_range("link.pose_rate", self.pose_rate, 0.1, 100.0)


def quat_from_euler(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp = math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


class LinkNode:
    def __init__(self, session: zenoh.Session, vehicle: str, cfg: LinkNodeConfig) -> None:
        self.session, self.keys, self.cfg = session, keys.Keys(vehicle), cfg
        self.rejects = Rejects(_log)
        self._t0 = time.monotonic()
        self.link = FlightLink(cfg.link, clock=self.clock)
        self._stop = threading.Event()
        self._sub = None
        self.waypoints = 0
        self._last_seq = -1
        self._thread = threading.Thread(target=self._publish_loop, name="link-pose", daemon=True)

    def clock(self) -> float:
        return time.monotonic() - self._t0

    def run(self, stop: threading.Event) -> None:
        """Connect, take off, then follow waypoints until ``stop``; a stop during the takeoff aborts it."""
        threading.Thread(target=lambda: (stop.wait(), self.link.close()), daemon=True).start()
        link = self.link
        try:
            link.connect()
            self._thread.start()  # pose from now on, so the ground sees the takeoff
            link.wait_ready()
            link.start_guided()
            link.arm()
            link.takeoff(self.cfg.takeoff_altitude)
        except LinkError:
            if stop.is_set():  # the waits end with an error when the link is closed
                return
            raise
        self._sub = self.session.declare_subscriber(self.keys.waypoint,
                                                    guarded(decode_waypoint, self._on_waypoint, self.rejects))
        wait_for_stop(stop)

    def _on_waypoint(self, w: Waypoint, key: str) -> None:
        if w.seq == self._last_seq:  # decide repeats its current waypoint until reached
            return
        self._last_seq = w.seq
        try:
            self.link.set_waypoint(*w.position, yaw=None if math.isnan(w.yaw) else w.yaw, face_waypoint=True)
            self.waypoints += 1
        except (LinkError, ValueError) as exc:  # outside the allowed area, or the pilot has the vehicle
            self.rejects.reject(key, BadMessage("waypoint refused", str(exc)))

    def _publish_loop(self) -> None:
        period = 1.0 / self.cfg.pose_rate
        while not self._stop.wait(period):
            t = self.link.telemetry()
            if not t.link_ok:
                continue
            battery = t.battery_remaining / 100.0 if 0 <= t.battery_remaining <= 100 else math.nan
            publish(self.session, self.keys.pose, encode_state(State(
                t.boot_time, self.keys.vehicle, t.position, quat_from_euler(t.roll, t.pitch, t.yaw), t.velocity,
                t.armed, t.mode, battery)))

    def stop(self) -> None:
        self._stop.set()
        if self._sub is not None:
            self._sub.undeclare()
        if self._thread.is_alive():
            self._thread.join()
        self.link.close()
