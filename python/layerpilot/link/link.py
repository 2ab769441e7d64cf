"""FlightLink: fly layerpilot's map-frame waypoints on ArduPilot (GUIDED) or PX4 (OFFBOARD).

One background thread owns the receive side: it tracks the autopilot's state,
sends our 1 Hz HEARTBEAT (as an onboard controller), re-sends the current
setpoint every ``setpoint_period_s`` and watches the failsafes. The public
methods are called from the mission thread and block with wall-clock timeouts.

Failsafes:
  * no autopilot HEARTBEAT for ``heartbeat_timeout_s`` -> link lost: setpoints stop,
    new waypoints raise :class:`LinkLost`, a running :meth:`goto` waits; when the
    link returns it resumes (or commands RTL/LAND if the loss lasted longer than
    ``long_loss_s`` and ``long_loss_action`` says so);
  * a waypoint outside the geofence (:class:`~layerpilot.link.geofence.Geofence`: the
    mission's area of interest plus a margin, and its altitude limits) raises
    :class:`WaypointRefused` before anything is sent, whoever asked (set_waypoint, goto,
    takeoff), and is counted in ``refused``; the worker checks every setpoint again right
    before it goes out. Without a fence (library and bench use only; every mission path
    gives one) the altitude limits of the config still apply;
  * a rejected COMMAND_ACK raises :class:`CommandRejected` naming the MAV_RESULT
    (and is reported even when nobody waits for it);
  * a mode change away from GUIDED/OFFBOARD made by someone else pauses the link
    until that mode is handed back (a pilot takeover); one that follows within
    ``FAILSAFE_TEXT_S`` a low-battery STATUSTEXT of the autopilot is its battery failsafe
    (ArduCopter "Battery 1 is low ...", PX4 "Low battery level! ..."): reported as
    ``autopilot failsafe: battery ...`` and kept in ``failsafe``, never as a takeover;
  * a reboot of the autopilot (its uptime, time_boot_ms, going backwards) is reported as
    such, never as a takeover: the link lets go of the vehicle (``reboots`` counts them);
    a disarm while the link flies makes the link ask for the streams and the uptime again
    (a rebooted ArduCopter forgot the message intervals asked of it) and is judged when the next
    uptime reading arrives: a reboot if it went back, else a disarm (also after ``UPTIME_WAIT_S``
    without one).
:meth:`FlightLink.fly_mission` hands the vehicle to its stored mission (ArduPilot AUTO) and
follows MISSION_CURRENT and MISSION_ITEM_REACHED; AUTO is then the mode the link flies in,
so another mode is a takeover as above.
Every wait (arrival, takeoff, readiness, the mission, the end action's acknowledgement) ends at once
with :class:`ControlLost` (``kind``: ``takeover``, ``failsafe``, ``disarmed`` or ``reboot``) when one
of these happens while it runs.
Every report goes to ``events`` (a list of strings), the ``on_event`` callback and
the ``layerpilot.link`` logger.
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from collections import Counter
from collections.abc import Callable

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.config import LinkConfig
from layerpilot.link.connection import open_connection
from layerpilot.link.frames import attitude_ned_to_enu, enu_to_ned, ned_to_enu, yaw_enu_to_ned
from layerpilot.link.geofence import Geofence, OutsideGeofence, check_altitude, check_finite
from layerpilot.link.telemetry import Telemetry

log = logging.getLogger("layerpilot.link")

POSITION_ONLY = 0b110111111000      # x, y, z used; velocity, acceleration, yaw, yaw rate ignored
POSITION_AND_YAW = 0b100111111000   # as above plus yaw
POSITION_FRESH_S = 2.0              # a position estimate older than this does not count
WAKE_S = 0.2                        # longest single sleep of a wait (see _wait)
RECONNECT_PERIOD_S = 1.0            # while lost, a stream connection (TCP, serial) is reopened this often
READY_STREAMS_S = 2.0               # while waiting for readiness, ask for the streams and the uptime again this often
READY_REPORT_S = 15.0               # while waiting for readiness, say what is still missing this often
END_ACTIONS = {"rtl": "RTL", "land": "LAND", "loiter": "LOITER"}  # mission end action -> the mode it puts
# ArduPilot's EKF_STATUS_REPORT flags: a horizontal position (absolute or relative) and not uninitialised
EKF_POSITION = mav.EKF_POS_HORIZ_ABS | mav.EKF_POS_HORIZ_REL
REBOOT_BACKSTEP_S = 1.0  # the autopilot's uptime went back by more than this: it rebooted
UPTIME_WAIT_S = 2.0      # a disarm waits at most this long for the uptime reading that tells a reboot
FAILSAFE_TEXT_S = 5.0    # a mode change this soon after a low-battery STATUSTEXT is the autopilot's failsafe
LOW_BATTERY_TEXT = re.compile(r"batt\w*\b.*\b(low|critical|failsafe|emergency)|(low|critical|emergency)\b.*batt",
                              re.IGNORECASE)  # ArduPilot's and PX4's low-battery warnings
UPTIME_MESSAGES = ("ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "SYSTEM_TIME")  # time_boot_ms


class LinkError(RuntimeError):
    """The flight link could not do what was asked; the message says why."""


class LinkLost(LinkError):
    """No HEARTBEAT from the autopilot within the timeout."""


class NotReady(LinkError):
    """The vehicle did not become ready in time; ``missing`` lists what was still missing."""

    def __init__(self, message: str, missing: list[str]) -> None:
        super().__init__(message)
        self.missing = missing


class CommandRejected(LinkError):
    """The autopilot answered a command with something other than MAV_RESULT_ACCEPTED."""

    def __init__(self, command: int, result: int, detail: str = "") -> None:
        self.command, self.result = command, result
        self.result_name = modes.result_name(result)
        super().__init__(f"{modes.command_name(command)} rejected: {self.result_name}{detail}")


class ControlLost(LinkError):
    """A wait ended because the vehicle was taken over, failed safe, disarmed or rebooted; ``kind``
    says which (``takeover``, ``failsafe``, ``disarmed``, ``reboot``)."""

    def __init__(self, message: str, kind: str) -> None:
        super().__init__(message)
        self.kind = kind


class WaypointRefused(LinkError, ValueError):
    """A waypoint outside the geofence (area or altitude) or not finite; nothing was sent.
    ``kind``: ``not finite``, ``outside the area`` or ``altitude``."""

    def __init__(self, message: str, kind: str) -> None:
        super().__init__(message)
        self.kind = kind


class FlightLink:
    """A companion-computer MAVLink link to one autopilot. Use as a context manager or call close()."""

    def __init__(self, config: LinkConfig | None = None, clock: Callable[[], float] = time.monotonic,
                 on_event: Callable[[str], None] | None = None, geofence: Geofence | None = None) -> None:
        self.config = config if config is not None else LinkConfig()
        self.geofence = geofence
        self.clock = clock
        self.on_event = on_event
        self.events: list[str] = []
        self.refused: Counter[str] = Counter()  # refused waypoints by kind (see WaypointRefused)
        self._send_lock = threading.Lock()
        self._conn = None
        self._connection_error = ""
        self._reopen_at = 0.0
        self._open()
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._interrupted = threading.Event()  # interrupt(): the waits end, the connection stays up
        # autopilot state (guarded by _cond)
        self.flavour: str | None = None
        self.target_system = self.config.target_system
        self.target_component = self.config.target_component
        self._last_heartbeat = -math.inf
        self._link_ok = False
        self._lost_at = 0.0
        self._armed = False
        self._mode = ""
        self._prearm_ok = False
        self._unhealthy: list[str] = []
        self._gps_fix = -1
        self._position_at = -math.inf
        self._ekf_flags: int | None = None  # ArduPilot EKF_STATUS_REPORT flags, once one arrived
        self._pose_time = 0.0
        self._boot_time = 0.0
        self._position = np.zeros(3)
        self._velocity = np.zeros(3)
        self._attitude = (0.0, 0.0, 0.0)
        self._home: np.ndarray | None = None
        self._battery = (0.0, -1)
        self._acks: dict[int, int] = {}
        self._waited: set[int] = set()
        self._texts: list[str] = []
        self._low_battery: tuple[float, str] | None = None  # (monotonic, text) of the newest low-battery STATUSTEXT
        self.failsafe = ""          # the autopilot's own failsafe took the vehicle (what it said), if it did
        # control state
        self._in_control = False    # we put the vehicle in GUIDED/OFFBOARD and fly it
        self._auto = False          # ... or in AUTO, flying its stored mission (fly_mission)
        self._mission_current = -1  # the autopilot's MISSION_CURRENT.seq, and the items it reached
        self._reached: list[int] = []
        self._paused = False        # the pilot took over
        self._setpoint: tuple[np.ndarray, float | None, tuple[float, float] | None, bool] | None = None
        self._stream_hold = False   # PX4: stream the current position (pre-arm, takeoff prep, pause)
        self._long_loss_command: int | None = None
        self._abandoned = ""        # why the current waypoint was dropped (long loss, land/RTL requested)
        self.upsets: list[tuple[str, str]] = []  # (kind, what happened): takeovers, disarms, reboots
        self.reboots = 0
        self.uptimes_before_reboot: list[float] = []  # the autopilot's uptime (s) when each reboot cut it
        self._uptime = -math.inf    # the autopilot's newest time_boot_ms (s): a step back is a reboot
        self._disarmed_at: float | None = None  # an unexplained disarm, judged by the next uptime reading
        self._uptime_at = -math.inf  # when (monotonic) the newest uptime reading arrived
        self._rebooted = False      # the worker re-requests the streams a reboot forgot
        self._thread = threading.Thread(target=self._loop, name="flight-link", daemon=True)
        self._thread.start()

    # --- lifecycle -------------------------------------------------------------------
    def connect(self, timeout: float | None = None) -> str:
        """Wait for an ArduPilot/PX4 HEARTBEAT, ask for telemetry streams; returns the autopilot flavour."""
        timeout = self.config.connect_timeout_s if timeout is None else timeout
        if not self._wait(lambda: self._link_ok, timeout):
            why = f" ({self._connection_error})" if self._conn is None and self._connection_error else ""
            raise LinkLost(f"no ArduPilot/PX4 HEARTBEAT on {self.config.url} within {timeout:.1f} s{why}")
        self._request_streams()
        return self.flavour

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._close_connection()

    def interrupt(self) -> None:
        """End every wait of the mission thread (they raise :class:`LinkError`) and refuse further
        commands, but keep the connection: :meth:`end_mission` can still command the end action."""
        self._interrupted.set()
        with self._cond:
            self._cond.notify_all()

    def __enter__(self) -> FlightLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- state -----------------------------------------------------------------------
    @property
    def link_ok(self) -> bool:
        return self._link_ok

    @property
    def paused(self) -> bool:
        return self._paused

    @property
    def mode(self) -> str:
        return self._mode

    @property
    def armed(self) -> bool:
        return self._armed

    @property
    def position_valid(self) -> bool:
        """The autopilot has a position: a LOCAL_POSITION_NED arrived and, if it reports its EKF
        (ArduPilot's EKF_STATUS_REPORT), the EKF has a horizontal position. Until then the
        position is (0, 0, 0) and means nothing."""
        return self._position_at > -math.inf and self._ekf_position_ok()

    def _ekf_position_ok(self) -> bool:
        flags = self._ekf_flags
        return flags is None or bool(flags & EKF_POSITION and not flags & mav.EKF_UNINITIALIZED)

    def telemetry(self) -> Telemetry:
        with self._cond:
            roll, pitch, yaw = self._attitude
            return Telemetry(self._pose_time, self._boot_time, self._position.copy(), self._velocity.copy(),
                             roll, pitch, yaw, self._armed, self._mode, self.flavour or "",
                             self._battery[0], self._battery[1],
                             self._link_ok, time.monotonic() - self._last_heartbeat,
                             None if self._home is None else self._home.copy(), self._paused)

    def missing(self) -> list[str]:
        """What still keeps the vehicle from being ready to fly (empty when ready)."""
        out = []
        if not self._link_ok:
            out.append("autopilot HEARTBEAT" + (" (none heard yet)" if self.flavour is None else
                                                f" (none for {time.monotonic() - self._last_heartbeat:.0f} s)"))
        if not self._prearm_ok:
            out.append("pre-arm checks (SYS_STATUS)" + (f": unhealthy {', '.join(self._unhealthy)}"
                                                         if self._unhealthy else ""))
        if self._gps_fix != -1 and self._gps_fix < mav.GPS_FIX_TYPE_3D_FIX:
            out.append(f"GPS 3D fix (fix_type {self._gps_fix})")
        if not self._ekf_position_ok():
            out.append(f"EKF position (EKF_STATUS_REPORT flags 0x{self._ekf_flags:x})")
        if time.monotonic() - self._position_at > POSITION_FRESH_S:
            out.append("position estimate (LOCAL_POSITION_NED)")
        if self._home is None:
            out.append("home position (HOME_POSITION)")
        return out

    def wait_ready(self, timeout: float | None = None) -> None:
        """Block until pre-arm checks pass and a position estimate and home arrive; NotReady names what is missing."""
        timeout = self.config.ready_timeout_s if timeout is None else timeout
        start = time.monotonic()
        deadline = start + timeout
        next_home_request = 0.0
        next_streams = start + READY_STREAMS_S
        next_report = start + READY_REPORT_S
        upsets = len(self.upsets)
        while self.missing():
            self._check_interrupted("waiting for the autopilot to be ready")
            self._check_upsets(upsets, "waiting for the autopilot to be ready")
            now = time.monotonic()
            if now >= deadline:
                missing = self.missing()
                texts = [t for t in self._texts[-5:] if "arm" in t.lower() or "fail" in t.lower()]
                raise NotReady(f"vehicle not ready after {timeout:.1f} s; missing: {'; '.join(missing)}"
                               + (f"; autopilot says: {' | '.join(texts)}" if texts else ""), missing)
            if now >= next_report:  # a cold-started SITL takes tens of seconds: say what it still lacks
                next_report = now + READY_REPORT_S
                self._report(f"waiting for the autopilot to be ready ({now - start:.0f} s of {timeout:.0f} s); "
                             f"missing: {'; '.join(self.missing())}", logging.INFO)
            if self._home is None and self._link_ok and time.monotonic() >= next_home_request:
                self._command_long(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_HOME_POSITION)
                next_home_request = time.monotonic() + 1.0
            if self._link_ok and time.monotonic() >= next_streams:  # a reboot meanwhile forgot them (or one was lost)
                self._ask_uptime()
                next_streams = time.monotonic() + READY_STREAMS_S
            self._wait(lambda: False, 0.1)

    # --- flying ----------------------------------------------------------------------
    def set_mode(self, name: str) -> None:
        """Command flight mode ``name`` (ArduCopter or PX4 name) and wait until the HEARTBEAT shows it."""
        self._require_link()
        self.command(mav.MAV_CMD_DO_SET_MODE, *self._mode_params(name))
        if not self._wait(lambda: self._mode == name, self.config.mode_timeout_s):
            raise LinkError(f"mode {name} accepted but the HEARTBEAT still says {self._mode}")

    def _mode_params(self, name: str) -> tuple[float, ...]:
        """DO_SET_MODE's parameters for mode ``name`` (ArduCopter custom mode; PX4 main/sub mode)."""
        custom = modes.custom_mode_of(self.flavour, name)
        if self.flavour == modes.PX4:
            return mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, (custom >> 16) & 0xFF, (custom >> 24) & 0xFF
        return mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom

    def end_mission(self, action: str, timeout: float) -> tuple[bool, str]:
        """The mission's end: command ``action`` (``rtl``, ``land`` or ``loiter``) and wait at most
        ``timeout`` s for its COMMAND_ACK and the HEARTBEAT's mode change. Returns (acknowledged,
        what happened); never raises. Clears :meth:`interrupt`; nothing is sent to a disarmed vehicle
        (it is on the ground) nor over a lost link. The current waypoint is dropped first."""
        what = END_ACTIONS[action]
        self._interrupted.clear()
        deadline = time.monotonic() + timeout
        if self.flavour is None:
            return self._ended(False, f"{what} not sent: no autopilot heard on {self.config.url}")
        if not self._link_ok:
            return self._ended(False, f"{what} not sent: link lost (no HEARTBEAT for "
                                      f"{time.monotonic() - self._last_heartbeat:.1f} s)")
        if not self._armed:
            return self._ended(True, f"{what} not needed: the vehicle is disarmed (on the ground, mode {self._mode})")
        with self._cond:
            self._in_control, self._paused, self._setpoint, self._stream_hold = False, False, None, False
            self._abandoned = f"mission end: {what}"
        command, params = {"rtl": (mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, ()), "land": (mav.MAV_CMD_NAV_LAND, ()),
                           "loiter": (mav.MAV_CMD_DO_SET_MODE, self._mode_params(what))}[action]
        with self._cond:
            self._waited.add(command)
            self._acks.pop(command, None)
        result, tries, upsets = None, 0, len(self.upsets)

        def reboot() -> str:  # what a reboot during this wait said ("" if none): the wait ends at once
            return next((text for kind, text in self.upsets[upsets:] if kind == "reboot"), "")

        try:
            while result is None and time.monotonic() < deadline and self._link_ok and not self._stop.is_set():
                self._command_long(command, *params, confirmation=tries)
                tries += 1
                left = min(self.config.command_timeout_s, deadline - time.monotonic())
                if self._wait(lambda: reboot() or self._acks.get(command, mav.MAV_RESULT_IN_PROGRESS)
                              != mav.MAV_RESULT_IN_PROGRESS, left):
                    if reboot():
                        return self._ended(False, f"{what} not acknowledged: {reboot()}")
                    result = self._acks[command]
        finally:
            with self._cond:
                self._waited.discard(command)
        if result is None:
            why = "link lost" if not self._link_ok else f"no COMMAND_ACK after {tries} tries in {timeout:.1f} s"
            return self._ended(False, f"{what} not acknowledged: {why}")
        if result != mav.MAV_RESULT_ACCEPTED:
            return self._ended(False, f"{what} rejected: {modes.result_name(result)}")
        if not self._wait(lambda: self._mode == what or reboot(), max(0.0, deadline - time.monotonic())):
            return self._ended(False, f"{what} accepted (COMMAND_ACK) but the HEARTBEAT still says mode "
                                      f"{self._mode} after {timeout:.1f} s")
        if reboot():
            return self._ended(False, f"{what} accepted, then {reboot()}")
        return self._ended(True, f"{what} acknowledged (COMMAND_ACK accepted, mode {what})")

    def _ended(self, ok: bool, text: str) -> tuple[bool, str]:
        self._report(f"mission end: {text}", logging.INFO if ok else logging.WARNING)
        return ok, text

    def _check_interrupted(self, doing: str) -> None:
        if self._interrupted.is_set():
            raise LinkError(f"interrupted while {doing}")

    def _check_upsets(self, since: int, doing: str) -> None:
        """:class:`ControlLost` if a takeover, disarm or reboot happened after upset number ``since``
        (a reboot names itself even when the disarm it caused came first)."""
        new = self.upsets[since:]
        if new:
            kind, text = next((u for u in new if u[0] == "reboot"), new[-1])
            raise ControlLost(f"{doing}: {text}", kind)

    def start_guided(self) -> None:
        """Take control: GUIDED on ArduPilot; on PX4 stream setpoints for ``offboard_prestream_s`` then OFFBOARD."""
        self._require_link()
        guided = modes.GUIDED_MODE[self.flavour]
        self._auto = False
        if self.flavour == modes.PX4:
            with self._cond:
                self._stream_hold = True
            self._wait(lambda: False, self.config.offboard_prestream_s)
        self._in_control, self._paused = True, False
        if self._mode != guided:
            try:
                self.set_mode(guided)
            except LinkError:
                self._in_control = False
                raise

    def arm(self, timeout: float | None = None) -> None:
        """Arm, retrying while the autopilot refuses (e.g. pre-arm checks still settling) until ``timeout``."""
        timeout = self.config.arm_timeout_s if timeout is None else timeout
        deadline = time.monotonic() + timeout
        while not self._armed:
            try:
                self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            except CommandRejected as exc:
                if time.monotonic() >= deadline:
                    texts = [t for t in self._texts[-3:]]
                    raise CommandRejected(exc.command, exc.result,
                                          f" (gave up after {timeout:.1f} s; autopilot says: {' | '.join(texts)})")
                self._wait(lambda: False, min(1.0, max(0.0, deadline - time.monotonic())))
                continue
            if not self._wait(lambda: self._armed, self.config.mode_timeout_s):
                raise LinkError("arming accepted but the HEARTBEAT does not show the vehicle armed")

    def takeoff(self, altitude: float, timeout: float | None = None) -> None:
        """Climb to ``altitude`` metres above home and hold there (NAV_TAKEOFF; PX4: an OFFBOARD setpoint)."""
        self._require_link()
        if not self._armed:
            raise LinkError("takeoff: the vehicle is not armed")
        home = self._home_or_error()
        check = self._check_waypoint(self._position[0], self._position[1], home[2] + altitude)
        if self.flavour == modes.ARDUPILOT:
            upsets = len(self.upsets)
            self.command(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, altitude)
            target = check
            timeout = timeout if timeout is not None else 30.0 + 2.0 * altitude
            if not self._wait_arrival(target, timeout, use_setpoint=False, upsets=upsets, doing="takeoff"):
                raise LinkError(f"takeoff: did not reach {altitude:.1f} m within {timeout:.1f} s")
            self._set_setpoint(target, None, None, False)
        else:
            self.goto(*check, timeout=timeout)

    def check_waypoint(self, x: float, y: float, z: float) -> np.ndarray:
        """The map-frame waypoint as an array if the geofence allows it, else :class:`WaypointRefused`
        (counted in ``refused``). Sends nothing."""
        return self._check_waypoint(x, y, z)

    @property
    def refused_total(self) -> int:
        return sum(self.refused.values())

    def set_waypoint(self, x: float, y: float, z: float, yaw: float | None = None,
                     look_at: tuple[float, float] | None = None, face_waypoint: bool = False) -> np.ndarray:
        """Start flying to map-frame (x, y, z) without waiting; the worker re-sends it. Returns the waypoint.

        ``yaw`` (ENU radians), ``look_at`` (a map point to face, e.g. an orbit centre) or
        ``face_waypoint`` choose the heading; by default the autopilot keeps its own.
        """
        target = self._check_waypoint(x, y, z)
        self._require_link()
        if self._paused:
            raise LinkError(f"paused: the pilot has the vehicle in {self._mode}; hand back "
                            f"{modes.GUIDED_MODE[self.flavour]} to continue")
        if not self._in_control:
            raise LinkError("not in control: call start_guided() first")
        self._set_setpoint(target, yaw, look_at, face_waypoint)
        return target

    def goto(self, x: float, y: float, z: float, yaw: float | None = None,
             look_at: tuple[float, float] | None = None, face_waypoint: bool = False,
             timeout: float | None = None) -> None:
        """Fly to map-frame (x, y, z) and return once within the tolerance for ``arrival_hold_s``.

        Waits out link losses (they do not count as arrival); raises LinkLost when the link came
        back after a long loss and the configured action was taken, and :class:`ControlLost` at
        once when the pilot takes over, the vehicle disarms or the autopilot reboots.
        """
        upsets = len(self.upsets)
        target = self.set_waypoint(x, y, z, yaw, look_at, face_waypoint)
        if timeout is None:
            timeout = 60.0 + 3.0 * float(np.linalg.norm(target - self._position))
        if not self._wait_arrival(target, timeout, use_setpoint=True, upsets=upsets, doing="goto"):
            raise LinkError(f"goto: did not arrive at ({x:.1f}, {y:.1f}, {z:.1f}) within {timeout:.1f} s "
                            f"(now at {np.round(self._position, 1).tolist()})")

    def set_speed(self, speed: float | None) -> None:
        """Cruise at ``speed`` m/s over ground (DO_CHANGE_SPEED), or the autopilot's default for None.

        A survey flies at the speed its camera rate allows (frames far enough apart for
        stereo, close enough to overlap). ArduCopter applies it to GUIDED position targets;
        PX4 ignores it in OFFBOARD, where MPC_XY_VEL_MAX rules.
        """
        if speed is not None and not (math.isfinite(speed) and speed > 0.0):
            raise ValueError(f"speed: must be a positive number of m/s, got {speed}")
        self.command(mav.MAV_CMD_DO_CHANGE_SPEED, 1.0, -2.0 if speed is None else float(speed), -1.0)

    def fly_mission(self, last: int, timeout: float,
                    progress: Callable[[str, int], None] | None = None) -> None:
        """Fly the vehicle's stored mission in AUTO until item ``last`` is reached (MISSION_ITEM_REACHED).

        ArduPilot only, armed and flying (ArduCopter refuses AUTO on the ground without a takeoff item).
        ``progress("current", seq)`` on each new MISSION_CURRENT item, ``progress("reached", seq)`` on
        each MISSION_ITEM_REACHED. Raises :class:`ControlLost` at once on a takeover (any other mode),
        a disarm or a reboot, and LinkError when ``last`` is not reached within ``timeout`` seconds.
        The vehicle stays in AUTO afterwards (ArduCopter loiters at the mission's end).
        """
        self._require_link()
        auto = modes.MISSION_MODE.get(self.flavour)
        if auto is None:
            raise LinkError(f"fly_mission: stored missions are flown in ArduPilot's AUTO only (this is {self.flavour})")
        if not self._armed:
            raise LinkError("fly_mission: the vehicle is not armed (take off first: ArduCopter refuses AUTO on "
                            "the ground unless the mission starts with a takeoff)")
        upsets = len(self.upsets)
        with self._cond:
            self._setpoint, self._stream_hold, self._abandoned = None, False, ""
            self._in_control, self._paused, self._auto = True, False, True
            self._mission_current, self._reached = -1, []
        self._command_long(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_MISSION_CURRENT, 1e6)
        try:
            self.set_mode(auto)
        except LinkError:
            with self._cond:
                self._in_control = self._auto = False
            raise
        deadline = time.monotonic() + timeout
        told = (-1, 0)
        while True:
            self._check_interrupted("flying the mission")
            self._check_upsets(upsets, "flying the mission")
            with self._cond:
                current, reached = self._mission_current, list(self._reached)
            if progress is not None:  # in the vehicle's order: an item reached, then the next one current
                for seq in reached[told[1]:]:
                    progress("reached", seq)
                if current != told[0] and current >= 0:
                    progress("current", current)
            told = (current, len(reached))
            if last in reached:
                return
            if time.monotonic() >= deadline:
                raise LinkError(f"mission: item {last} not reached within {timeout:.1f} s (flying item {current}, "
                                f"reached {reached or 'none'})")
            self._wait(lambda: (self._mission_current, len(self._reached)) != told or len(self.upsets) > upsets,
                       deadline - time.monotonic())

    def land(self, wait: bool = True, timeout: float = 180.0) -> None:
        """Land where the vehicle is (NAV_LAND); with ``wait``, until it has disarmed.

        A disarmed vehicle is on the ground: nothing to land, LinkError (nothing is sent)."""
        self._require_armed("LAND")
        self._release(mav.MAV_CMD_NAV_LAND, "LAND", wait, timeout)

    def rtl(self, wait: bool = True, timeout: float = 300.0) -> None:
        """Return to launch and land (NAV_RETURN_TO_LAUNCH); with ``wait``, until it has disarmed.

        A disarmed vehicle is on the ground: nothing to return from, LinkError (nothing is sent)."""
        self._require_armed("RTL")
        self._release(mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, "RTL", wait, timeout)

    def _require_armed(self, what: str) -> None:
        self._require_link()
        if not self._armed:
            raise LinkError(f"{what}: the vehicle is disarmed (on the ground, mode {self._mode}); nothing sent")

    def command(self, command: int, *params: float) -> None:
        """Send COMMAND_LONG and wait for its ACK; CommandRejected unless MAV_RESULT_ACCEPTED."""
        self._require_link()
        self._check_interrupted(f"sending {modes.command_name(command)}")
        result = self._command_ack(command, params)
        if result != mav.MAV_RESULT_ACCEPTED:
            raise CommandRejected(command, result)

    # --- internals: commands ---------------------------------------------------------
    def _release(self, command: int, what: str, wait: bool, timeout: float) -> None:
        with self._cond:
            self._in_control, self._paused, self._setpoint, self._stream_hold = False, False, None, False
            self._abandoned = f"{what} requested"
        self.command(command)
        if wait and not self._wait(lambda: not self._armed, timeout):
            raise LinkError(f"{what}: still armed after {timeout:.1f} s")

    def _command_ack(self, command: int, params: tuple[float, ...]) -> int:
        with self._cond:
            self._waited.add(command)
            self._acks.pop(command, None)
        try:
            for attempt in range(self.config.command_retries + 1):
                self._command_long(command, *params, confirmation=attempt)
                if self._wait(lambda: command in self._acks and self._acks[command] != mav.MAV_RESULT_IN_PROGRESS,
                              self.config.command_timeout_s):
                    result = self._acks[command]
                    if result != mav.MAV_RESULT_ACCEPTED:
                        self._report(f"{modes.command_name(command)} rejected: {modes.result_name(result)}")
                    return result
                if not self._link_ok:
                    raise LinkLost(f"{modes.command_name(command)}: link lost while waiting for COMMAND_ACK")
                self._check_interrupted(f"waiting for the COMMAND_ACK of {modes.command_name(command)}")
            raise LinkError(f"{modes.command_name(command)}: no COMMAND_ACK after "
                            f"{self.config.command_retries + 1} tries")
        finally:
            with self._cond:
                self._waited.discard(command)

    def _command_long(self, command: int, *params: float, confirmation: int = 0) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self._transmit(lambda m: m.command_long_send(self.target_system, self.target_component, command,
                                                      confirmation, *p))

    def _ask_uptime(self) -> None:
        """Ask for the streams and for SYSTEM_TIME at once: after a link loss or an unexpected disarm
        the uptime tells whether the autopilot rebooted, and a rebooted one streams nothing unasked."""
        self._request_streams()
        self._command_long(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_SYSTEM_TIME)

    def _request_streams(self) -> None:
        """Ask for the streams the link needs (ACKs checked by the worker: refusals are reported); real
        ArduCopter streams none unasked, so GPS and EKF readiness rest on GPS_RAW_INT and EKF_STATUS_REPORT
        asked for here (EKF_STATUS_REPORT is ArduPilot's alone)."""
        fast = 1e6 / self.config.telemetry_rate_hz
        for msg_id, interval in ((mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, fast), (mav.MAVLINK_MSG_ID_ATTITUDE, fast),
                                 (mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, fast), (mav.MAVLINK_MSG_ID_SYS_STATUS, 1e6),
                                 (mav.MAVLINK_MSG_ID_HOME_POSITION, 5e6), (mav.MAVLINK_MSG_ID_GPS_RAW_INT, 1e6),
                                 (mav.MAVLINK_MSG_ID_EKF_STATUS_REPORT, 1e6), (mav.MAVLINK_MSG_ID_SYSTEM_TIME, 1e6)):
            if msg_id != mav.MAVLINK_MSG_ID_EKF_STATUS_REPORT or self.flavour == modes.ARDUPILOT:
                self._command_long(mav.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval)

    # --- internals: waypoints --------------------------------------------------------
    def _home_or_error(self) -> np.ndarray:
        if self._home is None:
            raise LinkError("home position unknown (no HOME_POSITION yet): call wait_ready() first")
        return self._home

    def _check_waypoint(self, x: float, y: float, z: float) -> np.ndarray:
        """The geofence (or, without one, the config's altitude limits): WaypointRefused, counted."""
        x, y, z = float(x), float(y), float(z)
        try:
            self._fence_check(x, y, z)
        except OutsideGeofence as exc:
            self._refuse(exc)
        return np.array([x, y, z], dtype=np.float64)

    def _fence_check(self, x: float, y: float, z: float) -> None:
        fence = self.geofence
        if fence is not None:
            fence.check_area(x, y, z)  # needs no home: refused even before HOME_POSITION
        else:
            check_finite(x, y, z)
        home_z = float(self._home_or_error()[2])
        if fence is not None:
            fence.check(x, y, z, home_z)
        else:
            check_altitude(x, y, z, home_z, self.config.alt_min_m, self.config.alt_max_m)

    def _refuse(self, exc: OutsideGeofence) -> None:
        """Count and raise; the caller reports it (the link node logs each kind once, a command prints it)."""
        with self._cond:
            self.refused[exc.kind] += 1
        raise WaypointRefused(str(exc), exc.kind) from None

    def _set_setpoint(self, target: np.ndarray, yaw: float | None, look_at: tuple[float, float] | None,
                      face: bool) -> None:
        with self._cond:
            self._setpoint = (target, yaw, look_at, face)
            self._stream_hold, self._abandoned = False, ""
        self._send_setpoint()

    def _wait_arrival(self, target: np.ndarray, timeout: float, use_setpoint: bool, upsets: int, doing: str) -> bool:
        """True once within tolerance for arrival_hold_s with the link up and not paused; ControlLost
        as soon as an upset after number ``upsets`` (takeover, disarm, reboot) is known."""
        deadline = time.monotonic() + timeout
        since: float | None = None
        while time.monotonic() < deadline:
            if self._stop.is_set():
                raise LinkError("link closed")
            self._check_interrupted("flying to a waypoint")
            self._check_upsets(upsets, doing)
            if use_setpoint and self._abandoned:
                raise LinkLost(f"waypoint abandoned: {self._abandoned}") if "link loss" in self._abandoned \
                    else LinkError(f"waypoint abandoned: {self._abandoned}")
            fresh = time.monotonic() - self._position_at < POSITION_FRESH_S
            close = np.linalg.norm(self._position - target) <= self.config.arrival_tolerance_m
            if self._link_ok and fresh and close and not self._paused:
                since = time.monotonic() if since is None else since
                if time.monotonic() - since >= self.config.arrival_hold_s:
                    return True
            else:
                since = None
            self._wait(lambda: False, 0.05)
        return False

    def _send_setpoint(self) -> None:
        """Send the current setpoint now if the failsafes allow it (worker and mission thread)."""
        with self._cond:
            if not self._link_ok or self.flavour is None:
                return
            hold = self._stream_hold or (self._paused and self.flavour == modes.PX4)
            if hold:
                target, yaw = self._position.copy(), None
            elif self._setpoint is not None and self._in_control and not self._paused:
                target, yaw, look_at, face = self._setpoint
                yaw = self._heading(target, yaw, look_at, face)
            else:
                return
            if self.flavour == modes.ARDUPILOT and self._mode != "GUIDED":
                return
            dropped = None
            if not hold:  # the last gate: a setpoint no longer inside (home moved since) is dropped
                try:
                    self._fence_check(*target)
                except (OutsideGeofence, LinkError) as exc:  # LinkError: home unknown (cannot happen once set)
                    self._setpoint, self._abandoned, dropped = None, f"no longer inside the geofence: {exc}", exc
                    self.refused[getattr(exc, "kind", "altitude")] += 1
        if dropped is not None:
            self._report(f"setpoint dropped: {dropped}")
            return
        n, e, d = enu_to_ned(*target)
        mask = POSITION_ONLY if yaw is None else POSITION_AND_YAW
        self._transmit(lambda m: m.set_position_target_local_ned_send(
            int(time.monotonic() * 1000) & 0xFFFFFFFF, self.target_system, self.target_component,
            mav.MAV_FRAME_LOCAL_NED, mask, n, e, d, 0, 0, 0, 0, 0, 0,
            0.0 if yaw is None else yaw_enu_to_ned(yaw), 0))

    def _heading(self, target: np.ndarray, yaw: float | None, look_at: tuple[float, float] | None,
                 face: bool) -> float | None:
        if look_at is not None:
            dx, dy = look_at[0] - self._position[0], look_at[1] - self._position[1]
            return math.atan2(dy, dx) if math.hypot(dx, dy) > 1.0 else None
        if face:
            dx, dy = target[0] - self._position[0], target[1] - self._position[1]
            return math.atan2(dy, dx) if math.hypot(dx, dy) > 2.0 else None
        return yaw

    # --- internals: worker -----------------------------------------------------------
    def _loop(self) -> None:
        next_heartbeat = next_setpoint = 0.0
        while not self._stop.is_set():
            msg = None
            conn = self._conn
            if conn is None:
                self._stop.wait(0.02)
            else:
                try:
                    msg = conn.recv_match(blocking=True, timeout=0.02)
                except (OSError, ConnectionError) as exc:  # TCP reset, serial unplugged
                    self._report(f"connection error on {self.config.url}: {exc}; reconnecting")
                    self._close_connection()
            if msg is not None:
                self._on_message(msg)
            now = time.monotonic()
            if now >= next_heartbeat:
                next_heartbeat = now + 1.0
                self._transmit(lambda m: m.heartbeat_send(mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID,
                                                          0, 0, mav.MAV_STATE_ACTIVE))
            self._check_link(now)
            self._check_disarm(now)
            if self._rebooted:
                self._rebooted = False
                self._request_streams()  # a rebooted autopilot forgot the message intervals asked of it
            if now >= next_setpoint:
                next_setpoint = now + self.config.setpoint_period_s
                self._send_setpoint()
            stream = not self.config.url.startswith("udp")
            silent = now - self._last_heartbeat > self.config.heartbeat_timeout_s
            if now >= self._reopen_at and (self._conn is None or (stream and silent)):
                self._open()

    def _open(self) -> None:
        """(Re)open the connection once; on failure the worker tries again after RECONNECT_PERIOD_S."""
        self._reopen_at = time.monotonic() + RECONNECT_PERIOD_S
        self._close_connection()
        try:
            conn = open_connection(self.config.url, self.config.source_system, self.config.source_component,
                                   self.config.baud)
        except OSError as exc:
            self._connection_error = exc.strerror or str(exc)  # "Connection refused", not "[Errno 111] ..."
            return
        with self._send_lock:
            self._conn = conn

    def _close_connection(self) -> None:
        with self._send_lock:
            conn, self._conn = self._conn, None
        if conn is not None:
            try:
                conn.close()
            except (OSError, AttributeError):  # pymavlink's TCP close after a failed reconnect has no socket
                pass

    def _transmit(self, send: Callable) -> None:
        """Send with the connection's encoder; dropped while disconnected (the failsafes report that)."""
        with self._send_lock:
            if self._conn is None:
                return
            try:
                send(self._conn.mav)
            except OSError:
                pass

    def _check_link(self, now: float) -> None:
        if self._link_ok and now - self._last_heartbeat > self.config.heartbeat_timeout_s:
            with self._cond:
                self._link_ok = False
                self._lost_at = self._last_heartbeat
            self._report(f"link lost: no HEARTBEAT for {self.config.heartbeat_timeout_s:.1f} s; "
                         "no new waypoints until it returns")

    def _check_disarm(self, now: float) -> None:
        """A disarm while the link flies, reported once an uptime reading since did not go back (no
        reboot), or after UPTIME_WAIT_S without one."""
        with self._cond:
            if self._disarmed_at is None or (self._uptime_at <= self._disarmed_at
                                             and now - self._disarmed_at < UPTIME_WAIT_S):
                return
            self._disarmed_at = None
            text = f"the vehicle disarmed while the link was flying it (mode {self._mode}); waypoint abandoned"
            self._let_go("disarmed", text)
        self._report(text)

    def _let_go(self, kind: str, text: str) -> None:
        """(``_cond`` held) Record an upset and stop flying the vehicle: no setpoint, not in control."""
        self._in_control, self._paused, self._setpoint, self._stream_hold = False, False, None, False
        self._abandoned = text
        self.upsets.append((kind, text))
        self._cond.notify_all()

    def _on_reboot(self, uptime: float) -> str:
        """(``_cond`` held) The autopilot restarted: let go, forget what it must tell again (home, position)."""
        self.reboots += 1
        self.uptimes_before_reboot.append(self._uptime)
        self._disarmed_at = None
        text = (f"autopilot rebooted: its uptime went back from {self._uptime:.1f} s to {uptime:.1f} s; "
                f"{'ARMED' if self._armed else 'disarmed'} in {self._mode}"
                + ("; the link let go of the vehicle" if self._in_control else ""))
        self._let_go("reboot", text)
        self._home, self._position_at, self._ekf_flags, self._prearm_ok = None, -math.inf, None, False
        self._rebooted = True
        return text

    def _on_message(self, msg) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            self._on_heartbeat(msg)
            return
        if msg.get_srcSystem() != self.target_system or msg.get_srcComponent() != self.target_component:
            return
        rebooted = ""
        with self._cond:
            if kind in UPTIME_MESSAGES:
                uptime = msg.time_boot_ms / 1000.0
                if uptime < self._uptime - REBOOT_BACKSTEP_S:
                    rebooted = self._on_reboot(uptime)
                self._uptime, self._uptime_at = uptime, time.monotonic()
            if kind == "LOCAL_POSITION_NED":
                self._position = np.array(ned_to_enu(msg.x, msg.y, msg.z))
                self._velocity = np.array(ned_to_enu(msg.vx, msg.vy, msg.vz))
                self._position_at, self._pose_time = time.monotonic(), self.clock()
                self._boot_time = msg.time_boot_ms / 1000.0
            elif kind == "ATTITUDE":
                self._attitude = attitude_ned_to_enu(msg.roll, msg.pitch, msg.yaw)
            elif kind == "SYS_STATUS":
                present = msg.onboard_control_sensors_present
                healthy = msg.onboard_control_sensors_health
                self._prearm_ok = bool(healthy & mav.MAV_SYS_STATUS_PREARM_CHECK) or \
                    not present & mav.MAV_SYS_STATUS_PREARM_CHECK
                bad = present & msg.onboard_control_sensors_enabled & ~healthy & ~mav.MAV_SYS_STATUS_PREARM_CHECK
                self._unhealthy = [e.name.replace("MAV_SYS_STATUS_", "") for bit, e in
                                   mav.enums["MAV_SYS_STATUS_SENSOR"].items() if bit & bad and bit]
                self._battery = (msg.voltage_battery / 1000.0, msg.battery_remaining)
            elif kind == "EKF_STATUS_REPORT":
                self._ekf_flags = msg.flags
            elif kind == "GPS_RAW_INT":
                self._gps_fix = msg.fix_type
            elif kind == "HOME_POSITION":
                self._home = np.array(ned_to_enu(msg.x, msg.y, msg.z))
            elif kind == "MISSION_CURRENT":
                self._mission_current = msg.seq
            elif kind == "MISSION_ITEM_REACHED":
                self._reached.append(msg.seq)
            elif kind == "COMMAND_ACK":
                if msg.target_system in (0, self.config.source_system) and \
                        msg.target_component in (0, self.config.source_component):
                    self._acks[msg.command] = msg.result
                    if msg.command not in self._waited and msg.result not in (mav.MAV_RESULT_ACCEPTED,
                                                                              mav.MAV_RESULT_IN_PROGRESS):
                        self._report(f"{modes.command_name(msg.command)} rejected: {modes.result_name(msg.result)}")
            elif kind == "STATUSTEXT":
                self._texts = self._texts[-19:] + [msg.text]
                log.info("autopilot: %s", msg.text)
                if LOW_BATTERY_TEXT.search(msg.text):
                    self._low_battery = (time.monotonic(), msg.text)
            self._cond.notify_all()
        if rebooted:
            self._report(rebooted)

    def _on_heartbeat(self, msg) -> None:
        flavour = modes.flavour_of(msg.autopilot)
        if flavour is None or msg.type in (mav.MAV_TYPE_GCS, mav.MAV_TYPE_ONBOARD_CONTROLLER):
            return
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.flavour is None:
            if self.config.target_system not in (0, src[0]) or self.config.target_component not in (0, src[1]):
                return
            self.flavour, self.target_system, self.target_component = flavour, src[0], src[1]
            self._report(f"autopilot: {flavour} (system {src[0]}, component {src[1]}, MAV_TYPE {msg.type})",
                         logging.INFO)
        elif src != (self.target_system, self.target_component):
            return
        reports = []
        with self._cond:
            self._last_heartbeat = time.monotonic()
            was_armed, self._armed = self._armed, bool(msg.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
            old, self._mode = self._mode, modes.mode_name(self.flavour, msg.custom_mode)
            restored = not self._link_ok
            self._link_ok = True
            guided = modes.MISSION_MODE[self.flavour] if self._auto else modes.GUIDED_MODE[self.flavour]
            if restored and self._lost_at:
                reports += self._on_restored()
            disarmed = was_armed and not self._armed  # or rebooted: ask the uptime (nothing streams unasked)
            if disarmed and self._in_control:
                self._disarmed_at = time.monotonic()  # a reboot, or a disarm: the next uptime tells (_check_disarm)
            elif self._in_control and not self._paused and self._mode != guided and old == guided:
                if not (restored and self.flavour == modes.PX4 and self._mode == modes.HOLD_MODE[modes.PX4]):
                    self._paused = True
                    if failsafe := self._battery_failsafe():
                        self.failsafe = failsafe
                        reports.append(failsafe)
                        self.upsets.append(("failsafe", failsafe))
                    else:
                        reports.append(f"pilot took over: mode {self._mode}; paused until {guided} is handed back")
                        self.upsets.append(("takeover", reports[-1]))
            elif self._in_control and self._paused and self._mode == guided:
                self._paused = False
                reports.append(f"control handed back ({guided}); resuming")
            self._cond.notify_all()
        for text in reports:
            self._report(text)
        if restored and self._lost_at:
            self._after_restore()
        elif disarmed:
            self._ask_uptime()

    def _battery_failsafe(self) -> str:
        """What the autopilot's battery failsafe said, if the mode change just seen is one (else "")."""
        if self._low_battery is None or time.monotonic() - self._low_battery[0] > FAILSAFE_TEXT_S:
            return ""
        remaining = self._battery[1]
        left = f", {remaining}% left" if 0 <= remaining <= 100 else ""
        return f"autopilot failsafe: battery ({self._low_battery[1]}{left}): {self._mode}"

    def _on_restored(self) -> list[str]:
        lost_for = time.monotonic() - self._lost_at
        if lost_for > self.config.long_loss_s and self.config.long_loss_action != "none" and self._in_control:
            self._in_control, self._setpoint, self._stream_hold = False, None, False
            self._abandoned = f"the link commanded {self.config.long_loss_action.upper()} after a long link loss"
            self._long_loss_command = (mav.MAV_CMD_NAV_RETURN_TO_LAUNCH if self.config.long_loss_action == "rtl"
                                       else mav.MAV_CMD_NAV_LAND)
            return [f"link restored after {lost_for:.1f} s (> {self.config.long_loss_s:.1f} s): commanding "
                    f"{self.config.long_loss_action.upper()}"]
        self._long_loss_command = None
        return [f"link restored after {lost_for:.1f} s; resuming"]

    def _after_restore(self) -> None:
        """Worker side of a restored link: streams and uptime again, long-loss action, PX4 re-entry
        into OFFBOARD."""
        self._ask_uptime()
        if self._long_loss_command is not None:
            self._command_long(self._long_loss_command)
        elif self.flavour == modes.PX4 and self._in_control and self._mode == modes.HOLD_MODE[modes.PX4]:
            # PX4 fell back to hold while our stream was stopped: the stream is back, re-enter OFFBOARD
            main, sub = modes.PX4_MODES["OFFBOARD"]
            threading.Timer(self.config.offboard_prestream_s, self._command_long,
                            args=(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub)).start()

    def _require_link(self) -> None:
        if not self._link_ok or self.flavour is None:
            raise LinkLost(f"no link to the autopilot on {self.config.url}")

    def _wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Wait for ``predicate`` (False on timeout or close) in slices of WAKE_S: the caller may be a
        process's main thread, which must get back to the interpreter for a signal to be handled."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while not (predicate() or self._stop.is_set() or self._interrupted.is_set()):
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, WAKE_S))
            return predicate()

    def _report(self, text: str, level: int = logging.WARNING) -> None:
        self.events.append(text)
        log.log(level, "%s", text)
        if self.on_event is not None:
            self.on_event(text)
