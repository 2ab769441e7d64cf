"""FlightLink: fly layerpilot's map-frame waypoints on ArduPilot (GUIDED) or PX4 (OFFBOARD).

One background thread owns the receive side: it feeds the autopilot's messages to the state
tracker, sends our 1 Hz HEARTBEAT (as an onboard controller), re-sends the current setpoint
every ``setpoint_period_s`` and runs the failsafe checks. The public methods are called from
the mission thread and block with wall-clock timeouts; every wait (arrival, take-off, readiness,
the mission, the end action's acknowledgement) ends at once with :class:`ControlLost` when the
vehicle is taken over, fails safe, disarms or reboots while it runs.

The link is put together from parts, one responsibility each:

* :mod:`~layerpilot.link.connection` (``MavlinkPort``): the connection and its reopening;
* :mod:`~layerpilot.link.vehicle_state`: what the autopilot reported, readiness, telemetry;
* :mod:`~layerpilot.link.commands`: COMMAND_LONG/ACK, streams, modes, arming, speed;
* :mod:`~layerpilot.link.control`: who flies the vehicle, and the failsafe and reboot policy;
* :mod:`~layerpilot.link.guided`: the geofence, the setpoint stream, take-off and waypoints;
* :mod:`~layerpilot.link.auto`: the stored mission in AUTO;
* :mod:`~layerpilot.link.handover`: LAND, RTL and the mission's end action;
* :mod:`~layerpilot.link.sync`: the lock, waits and reports they share.

Every report goes to ``events`` (a list of strings), the ``on_event`` callback and the
``layerpilot.link`` logger.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable
from threading import Thread

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link.auto import fly_mission
from layerpilot.link.commands import Commands
from layerpilot.link.config import LinkConfig
from layerpilot.link.connection import MavlinkPort
from layerpilot.link.control import Control
from layerpilot.link.errors import CommandRejected, ControlLost, LinkError, LinkLost, NotReady, WaypointRefused
from layerpilot.link.geofence import Geofence
from layerpilot.link.separation import Separation
from layerpilot.link.guided import Guided
from layerpilot.link.handover import Handover
from layerpilot.link.sync import LinkSync
from layerpilot.link.telemetry import Telemetry
from layerpilot.link.vehicle_state import VehicleState

__all__ = ["FlightLink", "LinkError", "LinkLost", "NotReady", "CommandRejected", "ControlLost", "WaypointRefused"]

READY_STREAMS_S = 2.0    # while waiting for readiness, ask for the streams and the uptime again this often
READY_REPORT_S = 15.0    # while waiting for readiness, say what is still missing this often


class FlightLink:
    """A companion-computer MAVLink link to one autopilot. Use as a context manager or call close().

    ``clock`` stamps each pose (``Telemetry.time``: the mission clock); ``geofence`` bounds every
    waypoint; ``separation`` (a fleet's) refuses one too near another drone. The parts are public for inspection (``state``, ``commands``, ``control``, ``guided``);
    fly through the methods here.
    """

    def __init__(self, config: LinkConfig | None = None, clock: Callable[[], float] = time.monotonic,
                 on_event: Callable[[str], None] | None = None, geofence: Geofence | None = None,
                 separation: Separation | None = None) -> None:
        self.config = config if config is not None else LinkConfig()
        self.geofence, self.separation = geofence, separation
        self.sync = LinkSync(on_event)
        self.port = MavlinkPort(self.config.url, self.config.source_system, self.config.source_component,
                                self.config.baud)
        self.state = VehicleState(self.config, clock, self.sync)
        self.commands = Commands(self.config, self.state, self.port, self.sync)
        self.control = Control(self.config, self.state, self.commands, self.sync)
        self.guided = Guided(self.config, geofence, self.state, self.commands, self.control, self.port, self.sync,
                             separation)
        self._handover = Handover(self.config, self.state, self.commands, self.control, self.sync)
        self._thread = Thread(target=self._loop, name="flight-link", daemon=True)
        self._thread.start()

    # --- lifecycle -------------------------------------------------------------------
    def connect(self, timeout: float | None = None) -> str:
        """Wait for an ArduPilot/PX4 HEARTBEAT, ask for telemetry streams; returns the autopilot flavour."""
        timeout = self.config.connect_timeout_s if timeout is None else timeout
        if not self.sync.wait(lambda: self.state.link_ok, timeout):
            why = f" ({self.port.error})" if not self.port.is_open and self.port.error else ""
            raise LinkLost(f"no ArduPilot/PX4 HEARTBEAT on {self.config.url} within {timeout:.1f} s{why}")
        self.commands.request_streams()
        return self.state.flavour

    def close(self) -> None:
        self.sync.stop.set()
        self._thread.join(timeout=2.0)
        self.port.close()

    def interrupt(self) -> None:
        """End every wait of the mission thread (they raise :class:`LinkError`) and refuse further
        commands, but keep the connection: :meth:`end_mission` can still command the end action."""
        self.sync.interrupted.set()
        with self.sync.cond:
            self.sync.cond.notify_all()

    def __enter__(self) -> FlightLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- state -----------------------------------------------------------------------
    @property
    def events(self) -> list[str]:
        return self.sync.events

    @property
    def flavour(self) -> str | None:
        """``ardupilot`` or ``px4`` once the autopilot was heard, else None."""
        return self.state.flavour

    @property
    def target_system(self) -> int:
        """The autopilot's MAVLink system id (the configured one until it was heard)."""
        return self.state.target_system

    @property
    def target_component(self) -> int:
        return self.state.target_component

    @property
    def link_ok(self) -> bool:
        return self.state.link_ok

    @property
    def mode(self) -> str:
        return self.state.mode

    @property
    def armed(self) -> bool:
        return self.state.armed

    @property
    def position_valid(self) -> bool:
        """The autopilot has a position (see :attr:`VehicleState.position_valid`)."""
        return self.state.position_valid

    @property
    def paused(self) -> bool:
        return self.control.paused

    @property
    def failsafe(self) -> str:
        """What the autopilot's own failsafe said when it took the vehicle ("" if it did not)."""
        return self.control.failsafe

    @property
    def upsets(self) -> list[tuple[str, str]]:
        """(kind, what happened) of every takeover, failsafe, disarm and reboot while the link flew."""
        return self.control.upsets

    @property
    def reboots(self) -> int:
        return self.control.reboots

    @property
    def uptimes_before_reboot(self) -> list[float]:
        return self.control.uptimes_before_reboot

    @property
    def refused(self) -> Counter[str]:
        """Refused waypoints by kind (see :class:`WaypointRefused`)."""
        return self.guided.refused

    @property
    def refused_total(self) -> int:
        return sum(self.guided.refused.values())

    def telemetry(self) -> Telemetry:
        return self.state.telemetry(self.control.paused)

    def missing(self) -> list[str]:
        """What still keeps the vehicle from being ready to fly (empty when ready)."""
        return self.state.missing()

    def wait_ready(self, timeout: float | None = None) -> None:
        """Block until pre-arm checks pass and a position estimate and home arrive; NotReady names what is missing."""
        timeout = self.config.ready_timeout_s if timeout is None else timeout
        start = time.monotonic()
        deadline = start + timeout
        next_home_request = 0.0
        next_streams = start + READY_STREAMS_S
        next_report = start + READY_REPORT_S
        upsets = len(self.control.upsets)
        state = self.state
        while state.missing():
            self.sync.check_interrupted("waiting for the autopilot to be ready")
            self.control.check_upsets(upsets, "waiting for the autopilot to be ready")
            now = time.monotonic()
            if now >= deadline:
                missing = state.missing()
                texts = [t for t in state.texts[-5:] if "arm" in t.lower() or "fail" in t.lower()]
                raise NotReady(f"vehicle not ready after {timeout:.1f} s; missing: {'; '.join(missing)}"
                               + (f"; autopilot says: {' | '.join(texts)}" if texts else ""), missing)
            if now >= next_report:  # a cold-started SITL takes tens of seconds: say what it still lacks
                next_report = now + READY_REPORT_S
                self.sync.report(f"waiting for the autopilot to be ready ({now - start:.0f} s of {timeout:.0f} s); "
                                 f"missing: {'; '.join(state.missing())}", logging.INFO)
            if state.home is None and state.link_ok and time.monotonic() >= next_home_request:
                self.commands.send(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_HOME_POSITION)
                next_home_request = time.monotonic() + 1.0
            if state.link_ok and time.monotonic() >= next_streams:  # a reboot meanwhile forgot them (or one was lost)
                self.commands.ask_uptime()
                next_streams = time.monotonic() + READY_STREAMS_S
            self.sync.sleep(0.1)

    # --- flying ----------------------------------------------------------------------
    def command(self, command: int, *params: float) -> None:
        """Send COMMAND_LONG and wait for its ACK; CommandRejected unless MAV_RESULT_ACCEPTED."""
        self.commands.command(command, *params)

    def set_mode(self, name: str) -> None:
        """Command flight mode ``name`` (ArduCopter or PX4 name) and wait until the HEARTBEAT shows it."""
        self.commands.set_mode(name)

    def arm(self, timeout: float | None = None) -> None:
        """Arm, retrying while the autopilot refuses (e.g. pre-arm checks still settling) until ``timeout``."""
        self.commands.arm(timeout)

    def set_speed(self, speed: float | None) -> None:
        """Cruise at ``speed`` m/s over ground (DO_CHANGE_SPEED), or the autopilot's default for None."""
        self.commands.set_speed(speed)

    def start_guided(self) -> None:
        """Take control: GUIDED on ArduPilot; on PX4 stream setpoints for ``offboard_prestream_s`` then OFFBOARD."""
        self.guided.start()

    def takeoff(self, altitude: float, timeout: float | None = None) -> None:
        """Climb to ``altitude`` metres above home and hold there (NAV_TAKEOFF; PX4: an OFFBOARD setpoint)."""
        self.guided.takeoff(altitude, timeout)

    def check_waypoint(self, x: float, y: float, z: float) -> np.ndarray:
        """The map-frame waypoint as an array if the geofence allows it, else :class:`WaypointRefused`
        (counted in ``refused``). Sends nothing."""
        return self.guided.check(x, y, z)

    def set_waypoint(self, x: float, y: float, z: float, yaw: float | None = None,
                     look_at: tuple[float, float] | None = None, face_waypoint: bool = False,
                     separate: bool = True) -> np.ndarray:
        """Start flying to map-frame (x, y, z) without waiting (see :meth:`Guided.set_waypoint`)."""
        return self.guided.set_waypoint(x, y, z, yaw, look_at, face_waypoint, separate)

    def goto(self, x: float, y: float, z: float, yaw: float | None = None,
             look_at: tuple[float, float] | None = None, face_waypoint: bool = False,
             timeout: float | None = None) -> None:
        """Fly to map-frame (x, y, z) and return on arrival (see :meth:`Guided.goto`)."""
        self.guided.goto(x, y, z, yaw, look_at, face_waypoint, timeout)

    def fly_mission(self, last: int, timeout: float, progress: Callable[[str, int], None] | None = None) -> None:
        """Fly the vehicle's stored mission in ArduPilot's AUTO or PX4's AUTO.MISSION until item ``last`` is
        reached (MISSION_ITEM_REACHED; items count from modes.FIRST_ITEM).

        Armed and flying (ArduCopter refuses AUTO on the ground without a takeoff item).
        ``progress("current", seq)`` on each new MISSION_CURRENT item, ``progress("reached", seq)`` on
        each MISSION_ITEM_REACHED. Raises :class:`ControlLost` at once on a takeover (any other mode),
        a disarm or a reboot, and LinkError when ``last`` is not reached within ``timeout`` seconds.
        ArduCopter stays in AUTO afterwards (it loiters at the mission's end); PX4 switches to AUTO.LOITER.
        """
        fly_mission(self.state, self.commands, self.control, self.sync, last, timeout, progress)

    def land(self, wait: bool = True, timeout: float = 180.0) -> None:
        """Land where the vehicle is (NAV_LAND); with ``wait``, until it has disarmed.

        A disarmed vehicle is on the ground: nothing to land, LinkError (nothing is sent)."""
        self._handover.land_or_rtl(mav.MAV_CMD_NAV_LAND, "LAND", wait, timeout)

    def rtl(self, wait: bool = True, timeout: float = 300.0) -> None:
        """Return to launch and land (NAV_RETURN_TO_LAUNCH); with ``wait``, until it has disarmed.

        A disarmed vehicle is on the ground: nothing to return from, LinkError (nothing is sent)."""
        self._handover.land_or_rtl(mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, "RTL", wait, timeout)

    def end_mission(self, action: str, timeout: float) -> tuple[bool, str]:
        """The mission's end: command ``action`` (``rtl``, ``land`` or ``loiter``) and wait at most
        ``timeout`` s for its COMMAND_ACK and the HEARTBEAT's mode change. Returns (acknowledged,
        what happened); never raises. Clears :meth:`interrupt`; nothing is sent to a disarmed vehicle
        (it is on the ground) nor over a lost link. The current waypoint is dropped first."""
        return self._handover.end_mission(action, timeout)

    # --- the worker ------------------------------------------------------------------
    def _loop(self) -> None:
        next_heartbeat = next_setpoint = 0.0
        sync, port = self.sync, self.port
        while not sync.stop.is_set():
            msg = None
            if not port.is_open:
                sync.stop.wait(0.02)
            else:
                try:
                    msg = port.receive(0.02)
                except (OSError, ConnectionError) as exc:  # TCP reset, serial unplugged
                    sync.report(f"connection error on {self.config.url}: {exc}; reconnecting")
                    port.close()
            if msg is not None:
                self._on_message(msg)
            now = time.monotonic()
            if now >= next_heartbeat:
                next_heartbeat = now + 1.0
                port.transmit(lambda m: m.heartbeat_send(mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID,
                                                         0, 0, mav.MAV_STATE_ACTIVE))
            self.control.check(now)
            if now >= next_setpoint:
                next_setpoint = now + self.config.setpoint_period_s
                self.guided.send()
            port.keep_open(now, self.state.silent(now))

    def _on_message(self, msg) -> None:
        """Hand a received message to the state tracker, then to the command protocol and the policy."""
        if msg.get_type() == "HEARTBEAT":
            if self.state.identify(msg):
                with self.sync.cond:
                    beat = self.state.on_heartbeat(msg)
                    reports = self.control.on_heartbeat(beat)
                    self.sync.cond.notify_all()
                for text in reports:
                    self.sync.report(text)
                self.control.after_heartbeat(beat)
            return
        if not self.state.is_target(msg):
            return
        rebooted = ""
        with self.sync.cond:
            uptime_before = self.state.update(msg)
            if uptime_before is not None:
                rebooted = self.control.on_reboot(uptime_before, self.state.uptime)
            if msg.get_type() == "COMMAND_ACK":
                self.commands.on_ack(msg)
            self.sync.cond.notify_all()
        if rebooted:
            self.sync.report(rebooted)
