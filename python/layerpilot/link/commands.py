"""The command protocol: COMMAND_LONG answered by COMMAND_ACK, with retries; the telemetry streams the
link asks for; flight modes, arming and cruise speed.

A command is sent up to ``command_retries + 1`` times, ``command_timeout_s`` apart, until its
COMMAND_ACK; a refusal raises :class:`~layerpilot.link.errors.CommandRejected` naming the
MAV_RESULT, and one that nobody waits for (a stream request) is reported all the same.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.config import LinkConfig
from layerpilot.link.connection import MavlinkPort
from layerpilot.link.errors import CommandRejected, LinkError, LinkLost
from layerpilot.link.sync import LinkSync
from layerpilot.link.vehicle_state import VehicleState

DONE = (mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_IN_PROGRESS)  # answers that are no refusal


class Commands:
    """COMMAND_LONG/COMMAND_ACK to the link's autopilot, and the commands built on it."""

    def __init__(self, config: LinkConfig, state: VehicleState, port: MavlinkPort, sync: LinkSync) -> None:
        self.config, self.state, self.port, self.sync = config, state, port, sync
        self._acks: dict[int, int] = {}  # the newest MAV_RESULT per command (guarded by the link's lock)
        self._waited: set[int] = set()   # commands someone waits for (they report their own refusals)

    # --- the protocol -----------------------------------------------------------------
    def send(self, command: int, *params: float, confirmation: int = 0) -> None:
        """One COMMAND_LONG, nothing awaited (its refusal is reported when it comes)."""
        p = list(params) + [0.0] * (7 - len(params))
        self.port.transmit(lambda m: m.command_long_send(self.state.target_system, self.state.target_component,
                                                         command, confirmation, *p))

    def on_ack(self, msg) -> None:
        """Record a COMMAND_ACK addressed to us (the link's lock held)."""
        if msg.target_system in (0, self.config.source_system) and \
                msg.target_component in (0, self.config.source_component):
            self._acks[msg.command] = msg.result
            if msg.command not in self._waited and msg.result not in DONE:
                self.sync.report(f"{modes.command_name(msg.command)} rejected: {modes.result_name(msg.result)}")

    def command(self, command: int, *params: float) -> None:
        """Send COMMAND_LONG and wait for its ACK; CommandRejected unless MAV_RESULT_ACCEPTED."""
        self.state.require_link()
        self.sync.check_interrupted(f"sending {modes.command_name(command)}")
        result = self._acknowledged(command, params)
        if result != mav.MAV_RESULT_ACCEPTED:
            raise CommandRejected(command, result)

    def _acknowledged(self, command: int, params: tuple[float, ...]) -> int:
        """The MAV_RESULT of ``command`` after at most ``command_retries + 1`` tries; LinkLost, LinkError."""
        name = modes.command_name(command)
        with self._awaiting(command):
            for attempt in range(self.config.command_retries + 1):
                self.send(command, *params, confirmation=attempt)
                if self.sync.wait(lambda: self._acks.get(command, mav.MAV_RESULT_IN_PROGRESS)
                                  != mav.MAV_RESULT_IN_PROGRESS, self.config.command_timeout_s):
                    result = self._acks[command]
                    if result != mav.MAV_RESULT_ACCEPTED:
                        self.sync.report(f"{name} rejected: {modes.result_name(result)}")
                    return result
                if not self.state.link_ok:
                    raise LinkLost(f"{name}: link lost while waiting for COMMAND_ACK")
                self.sync.check_interrupted(f"waiting for the COMMAND_ACK of {name}")
            raise LinkError(f"{name}: no COMMAND_ACK after {self.config.command_retries + 1} tries")

    def acknowledged_before(self, command: int, params: tuple[float, ...], deadline: float,
                            cancel: Callable[[], bool]) -> tuple[int | None, int]:
        """Send ``command`` every ``command_timeout_s`` until its COMMAND_ACK, the ``deadline`` (monotonic),
        a lost link, close or ``cancel()``. Returns (its MAV_RESULT, or None without one; the tries)."""
        tries = 0
        with self._awaiting(command):
            while time.monotonic() < deadline and self.state.link_ok and not self.sync.stop.is_set():
                self.send(command, *params, confirmation=tries)
                tries += 1
                left = min(self.config.command_timeout_s, deadline - time.monotonic())
                if self.sync.wait(lambda: cancel() or self._acks.get(command, mav.MAV_RESULT_IN_PROGRESS)
                                  != mav.MAV_RESULT_IN_PROGRESS, left):
                    return (None if cancel() else self._acks[command]), tries
        return None, tries

    @contextmanager
    def _awaiting(self, command: int) -> Iterator[None]:
        """While a caller waits for ``command``'s new ACK: an older one does not count, and the caller
        reports a refusal itself."""
        with self.sync.cond:
            self._waited.add(command)
            self._acks.pop(command, None)
        try:
            yield
        finally:
            with self.sync.cond:
                self._waited.discard(command)

    # --- streams ----------------------------------------------------------------------
    def request_streams(self) -> None:
        """Ask for the streams the link needs (their ACKs are checked by the worker: refusals are reported);
        real ArduCopter streams none unasked, so GPS and EKF readiness rest on GPS_RAW_INT and
        EKF_STATUS_REPORT asked for here (EKF_STATUS_REPORT is ArduPilot's alone)."""
        fast = 1e6 / self.config.telemetry_rate_hz
        for msg_id, interval in ((mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, fast), (mav.MAVLINK_MSG_ID_ATTITUDE, fast),
                                 (mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, fast), (mav.MAVLINK_MSG_ID_SYS_STATUS, 1e6),
                                 (mav.MAVLINK_MSG_ID_HOME_POSITION, 5e6), (mav.MAVLINK_MSG_ID_GPS_RAW_INT, 1e6),
                                 (mav.MAVLINK_MSG_ID_EKF_STATUS_REPORT, 1e6), (mav.MAVLINK_MSG_ID_SYSTEM_TIME, 1e6)):
            if msg_id != mav.MAVLINK_MSG_ID_EKF_STATUS_REPORT or self.state.flavour == modes.ARDUPILOT:
                self.send(mav.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval)

    def ask_uptime(self) -> None:
        """Ask for the streams and for SYSTEM_TIME at once: after a link loss or an unexpected disarm
        the uptime tells whether the autopilot rebooted, and a rebooted one streams nothing unasked."""
        self.request_streams()
        self.send(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_SYSTEM_TIME)

    # --- modes, arming, speed ---------------------------------------------------------
    def mode_params(self, name: str) -> tuple[float, ...]:
        """DO_SET_MODE's parameters for mode ``name`` (ArduCopter custom mode; PX4 main/sub mode)."""
        custom = modes.custom_mode_of(self.state.flavour, name)
        if self.state.flavour == modes.PX4:
            return mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, (custom >> 16) & 0xFF, (custom >> 24) & 0xFF
        return mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom

    def set_mode(self, name: str) -> None:
        """Command flight mode ``name`` (ArduCopter or PX4 name) and wait until the HEARTBEAT shows it."""
        self.state.require_link()
        self.command(mav.MAV_CMD_DO_SET_MODE, *self.mode_params(name))
        if not self.sync.wait(lambda: self.state.mode == name, self.config.mode_timeout_s):
            raise LinkError(f"mode {name} accepted but the HEARTBEAT still says {self.state.mode}")

    def arm(self, timeout: float | None = None) -> None:
        """Arm, retrying while the autopilot refuses (e.g. pre-arm checks still settling) until ``timeout``."""
        timeout = self.config.arm_timeout_s if timeout is None else timeout
        deadline = time.monotonic() + timeout
        while not self.state.armed:
            try:
                self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            except CommandRejected as exc:
                if time.monotonic() >= deadline:
                    texts = self.state.texts[-3:]
                    raise CommandRejected(exc.command, exc.result,
                                          f" (gave up after {timeout:.1f} s; autopilot says: {' | '.join(texts)})")
                self.sync.sleep(min(1.0, max(0.0, deadline - time.monotonic())))
                continue
            if not self.sync.wait(lambda: self.state.armed, self.config.mode_timeout_s):
                raise LinkError("arming accepted but the HEARTBEAT does not show the vehicle armed")

    def set_speed(self, speed: float | None) -> None:
        """Cruise at ``speed`` m/s over ground (DO_CHANGE_SPEED), or the autopilot's default for None.

        A survey flies at the speed its camera rate allows (frames far enough apart for
        stereo, close enough to overlap). ArduCopter applies it to GUIDED position targets;
        PX4 ignores it in OFFBOARD, where MPC_XY_VEL_MAX rules.
        """
        if speed is not None and not (math.isfinite(speed) and speed > 0.0):
            raise ValueError(f"speed: must be a positive number of m/s, got {speed}")
        self.command(mav.MAV_CMD_DO_CHANGE_SPEED, 1.0, -2.0 if speed is None else float(speed), -1.0)
