"""The simulated multicopter's MAVLink 2 endpoint: it behaves like ArduCopter (or PX4).

Serves ``tcp:127.0.0.1:5760`` by default like ArduPilot's SITL (several clients
at once, e.g. MAVProxy and a script) and UDP when configured. Runs in lock-step
(``step(dt)`` advances the mission clock; tests and evaluation in one process)
or as a real-time loop (``run_realtime()`` / ``start()`` in a thread, optionally
faster than real time). ``pause_output()`` silences it for link-loss tests.

Frames: the vehicle lives in the map frame (ENU, z up), whose origin sits at the
geodetic point ``origin`` (the world's datum). Home is where the vehicle starts, on
the ground. Like ArduCopter and PX4, its MAVLink local NED frame has its origin at
the EKF origin, set at the first good position on the ground at home: LOCAL_POSITION_NED
reads z = 0 on the ground there and -30 at 30 m above it; ``ekf_origin`` is that point in
the map frame.

Sensors (``EndpointConfig.sensors``): the vehicle flies its true trajectory; every position
and attitude it reports carries the EKF's error, and like a real autopilot it flies position
setpoints in its estimated frame. Home and the EKF origin are reported exact.

:class:`MavlinkVehicle` owns the lock, the clock's step and the message dispatch, and puts
together parts with one job each, all sharing one :class:`~layerpilot.sim.autopilot_state.AutopilotState`:

* :mod:`~layerpilot.sim.endpoint_port`: the transports, the encoder, a parser per peer;
* :mod:`~layerpilot.sim.mode_commands`: arming, disarming, mode changes, take-off;
* :mod:`~layerpilot.sim.setpoints`: GUIDED and OFFBOARD setpoints;
* :mod:`~layerpilot.sim.flight`: failsafes, each mode's own flying, auto-disarm;
* :mod:`~layerpilot.sim.landing` and :mod:`~layerpilot.sim.auto_mode`: RTL and LAND, the stored mission;
* :mod:`~layerpilot.sim.streams` and :mod:`~layerpilot.sim.telemetry_sender`: what is sent when, and how.

Usage::

    vehicle = Multicopter(position=(0, 0, ground_z), ground_z=ground_z)
    endpoint = MavlinkVehicle(vehicle, ["tcp:127.0.0.1:5760"])
    endpoint.start(speed=1.0)      # or: endpoint.step(0.02) from your own loop
    ...
    endpoint.pose()                # VehiclePose in the map frame (the truth)
    endpoint.reported_pose()       # what the autopilot's EKF reports (the truth plus the sensors' errors)
    endpoint.stop()
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.config import check_range
from layerpilot.geodesy import LocalFrame
from layerpilot.link import modes
from layerpilot.sim.auto_mode import AutoMode
from layerpilot.sim.autopilot_state import AutopilotState
from layerpilot.sim.endpoint_config import DEFAULT_URL, SITL_DATUM, EndpointConfig
from layerpilot.sim.endpoint_port import EndpointPort
from layerpilot.sim.estimate import VehiclePose
from layerpilot.sim.flight import Flight
from layerpilot.sim.landing import Landing
from layerpilot.sim.mission_store import MESSAGES as MISSION_MESSAGES
from layerpilot.sim.mission_store import MissionStore
from layerpilot.sim.mode_commands import ModeCommands
from layerpilot.sim.setpoints import Setpoints
from layerpilot.sim.streams import DEFAULT_INTERVALS, Streams
from layerpilot.sim.telemetry_sender import EKF_FLAGS_GOOD, EKF_FLAGS_NO_GPS, TelemetrySender
from layerpilot.sim.vehicle import Multicopter

__all__ = ["MavlinkVehicle", "EndpointConfig", "VehiclePose", "DEFAULT_URL", "SITL_DATUM", "DEFAULT_INTERVALS",
           "EKF_FLAGS_GOOD", "EKF_FLAGS_NO_GPS", "FORCE_DISARM_MAGIC"]

FORCE_DISARM_MAGIC = 21196  # ArduPilot/PX4: param2 of ARM_DISARM that forces a disarm in flight
SETPOINT_MESSAGES = ("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT")


def _state(name: str, doc: str) -> property:
    """An attribute of the shared :class:`AutopilotState`, seen on the endpoint."""
    return property(lambda self: getattr(self.state, name), lambda self, value: setattr(self.state, name, value),
                    doc=doc)


class MavlinkVehicle:
    """A :class:`Multicopter` behind a MAVLink 2 autopilot interface (ArduCopter or PX4 conventions)."""

    time = _state("time", "The mission clock (seconds).")
    mode = _state("mode", "The flight mode's name (link.modes).")
    armed = _state("armed", "Whether the motors are armed.")
    flavour = _state("flavour", "``ardupilot`` or ``px4``.")
    home = _state("home", "Where the vehicle started, in the map frame.")
    ekf_origin = _state("ekf_origin", "The local NED frame's origin in the map frame: home on the ground.")
    boots = _state("boots", "How often the autopilot booted.")
    battery = _state("battery", "The pack (sim.battery.Battery).")
    estimator = _state("estimator", "The EKF's estimate of the pose (sim.estimate.Estimator).")

    def __init__(self, vehicle: Multicopter | None = None, urls: Sequence[str] | str = (DEFAULT_URL,),
                 config: EndpointConfig | None = None) -> None:
        self.vehicle = vehicle if vehicle is not None else Multicopter()
        self.config = config if config is not None else EndpointConfig()
        self.port = EndpointPort([urls] if isinstance(urls, str) else list(urls),
                                 self.config.system_id, self.config.component_id)
        self.state = AutopilotState(self.vehicle, self.config, self.port.mav)
        self.mission = MissionStore(self.port.mav)  # the mission protocol's vehicle side (upload, download)
        landing = Landing(self.state)
        self.auto = AutoMode(self.state, self.mission, landing)
        self.setpoints = Setpoints(self.state)
        self.commands = ModeCommands(self.state, self.auto, self.setpoints)
        self.flight = Flight(self.state, self.commands, self.auto, landing)
        self.telemetry = TelemetrySender(self.state, self.auto)
        self.streams = Streams(self.state, self.telemetry)
        self._lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    # --- public API ------------------------------------------------------------------
    @property
    def addresses(self) -> list[tuple[str, int]]:
        """Bound (host, port) of each transport, in the order of ``urls`` (useful with port 0)."""
        return self.port.addresses

    @property
    def ekf_frame(self) -> LocalFrame:
        """The EKF origin on the Earth (what GPS_GLOBAL_ORIGIN reports): where the autopilot's local frame,
        a mission's map frame, lies; a run directory's ``frame.json``."""
        lat, lon, alt = self.config.origin.to_geodetic(*self.ekf_origin)
        return LocalFrame(float(lat), float(lon), float(alt))

    @property
    def clients(self) -> int:
        return self.port.clients

    @property
    def messages_received(self) -> int:
        return self.port.messages_received

    @property
    def output_paused(self) -> bool:
        return self.port.paused

    @property
    def uptime(self) -> float:
        """Seconds since the autopilot booted (its time_boot_ms)."""
        return self.state.uptime

    def pose(self) -> VehiclePose:
        with self._lock:
            return self.state.pose()

    def reported_pose(self) -> VehiclePose:
        """The state the autopilot reports (its EKF's estimate): :meth:`pose` plus the sensors' errors."""
        with self._lock:
            return self.state.reported_pose()

    def restart_errors(self) -> None:
        """The sensors' errors from their seed again, from now on (``Estimator.restart``); the vehicle
        keeps its true state, so it goes on flying what its new estimate says."""
        with self._lock:
            self.state.estimator.restart(self.state.pose())

    def reported_pose_at(self, t: float) -> VehiclePose:
        """The reported state at mission time ``t`` (within the last few seconds), interpolated between reports."""
        with self._lock:
            pose = self.state.estimator.at(t)
            return self.state.pose() if pose is None else pose

    def pause_output(self) -> None:
        """Stop sending anything (the vehicle keeps flying and listening): a link loss seen from outside."""
        self.port.paused = True

    def resume_output(self) -> None:
        self.port.paused = False

    def reboot(self) -> None:
        """Restart the autopilot as a power cycle does: a new boot (time_boot_ms from 0, pre-arm checks and
        GPS fix again after ``prearm_delay_s``), disarmed on the ground at home in its first mode, message
        intervals back to their defaults (the ArduPilot flavour forgets every stream asked of it, as
        ArduCopter does), a mission flown afterwards from item 1. The sockets stay served (a radio or
        serial link sees the new boot; SITL's TCP clients would reconnect); the battery keeps its charge."""
        with self._lock:
            self.state.reboot()
            self.auto.forget()
            self.streams.reset()

    def step(self, dt: float) -> None:
        """Handle what arrived, advance the mission clock by ``dt`` seconds, send what is due."""
        with self._lock:
            self._poll()
            s = self.state
            s.time += dt
            self.flight.before_motion()
            self.vehicle.step(dt)
            drift = s.estimator.errors.current.drift
            s.estimator.step(dt, s.pose())
            if s.airborne and not s.exact_pose:  # in the air it flies its estimate; on the ground it stays
                self.vehicle.shift_target(drift - s.estimator.errors.current.drift)
            self.flight.after_motion(dt)
            self.streams.send_due()

    def run_realtime(self, speed: float = 1.0, dt: float = 0.02, stop: threading.Event | None = None) -> None:
        """Step in real time (``speed`` x faster when > 1) until ``stop`` is set or :meth:`stop` is called."""
        check_range("speed", speed, 1e-3, None)
        check_range("dt", dt, 1e-4, 1.0)
        stop = stop if stop is not None else self._stop
        wall0, sim0 = time.monotonic(), self.time
        while not stop.is_set():
            target = sim0 + (time.monotonic() - wall0) * speed
            steps = 0
            while self.time + dt <= target and steps < 1000:
                self.step(dt)
                steps += 1
            if steps == 0:
                with self._lock:
                    self._poll()
                stop.wait(min(0.005, dt / speed))

    def start(self, speed: float = 1.0, dt: float = 0.02) -> MavlinkVehicle:
        """Run :meth:`run_realtime` in a daemon thread; :meth:`stop` ends it and closes the sockets."""
        if self._thread is not None:
            raise RuntimeError("endpoint already started")
        self._stop.clear()
        self._thread = threading.Thread(target=self.run_realtime, args=(speed, dt), name="sim-vehicle",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self.close()

    def close(self) -> None:
        self.port.close()

    def __enter__(self) -> MavlinkVehicle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # --- message dispatch --------------------------------------------------------------
    def _poll(self) -> None:
        for msg in self.port.receive():
            self._handle(msg)

    def _for_me(self, msg: mav.MAVLink_message) -> bool:
        ts, tc = getattr(msg, "target_system", 0), getattr(msg, "target_component", 0)
        return ts in (0, self.config.system_id) and tc in (0, self.config.component_id)

    def _handle(self, msg: mav.MAVLink_message) -> None:
        """Route one received message to the part that answers it (commands get their COMMAND_ACK here)."""
        kind = msg.get_type()
        if kind == "SET_MODE" and msg.target_system == self.config.system_id:
            result = self.commands.set_mode_numbers(msg.base_mode, msg.custom_mode)
            self.port.mav.command_ack_send(mav.MAVLINK_MSG_ID_SET_MODE, result, 0, 0,
                                           msg.get_srcSystem(), msg.get_srcComponent())
        elif not self._for_me(msg):
            return
        elif kind in SETPOINT_MESSAGES:
            self.setpoints.handle(msg)
        elif kind == "COMMAND_LONG":
            result = self._command(msg)
            self.port.mav.command_ack_send(msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())
        elif kind == "REQUEST_DATA_STREAM" and self.flavour == modes.ARDUPILOT:
            self.streams.request_data_stream(msg.req_stream_id, msg.req_message_rate if msg.start_stop else 0)
        elif kind in MISSION_MESSAGES:
            self.mission.handle(msg)

    def _command(self, msg: mav.MAVLink_message) -> int:
        """A COMMAND_LONG's result (MAV_RESULT); unknown commands are UNSUPPORTED."""
        c, cmds = msg.command, self.commands
        if c == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            force = msg.param2 == FORCE_DISARM_MAGIC
            return cmds.arm(force) if msg.param1 == 1 else cmds.disarm(force)
        if c == mav.MAV_CMD_DO_SET_MODE:
            if self.flavour == modes.PX4:
                return cmds.set_mode_numbers(int(msg.param1), modes.px4_custom_mode(int(msg.param2), int(msg.param3)))
            return cmds.set_mode_numbers(int(msg.param1), int(msg.param2))
        if c == mav.MAV_CMD_NAV_TAKEOFF:
            return cmds.takeoff(msg.param7)
        if c == mav.MAV_CMD_NAV_LAND:
            return cmds.enter_mode("LAND")
        if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return cmds.enter_mode("RTL")
        if c == mav.MAV_CMD_DO_CHANGE_SPEED:
            return self.state.change_speed(msg.param2)
        if c == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self.streams.set_interval(int(msg.param1), msg.param2)
        if c == mav.MAV_CMD_REQUEST_MESSAGE:
            return self.streams.send_now(int(msg.param1))
        if c == mav.MAV_CMD_GET_HOME_POSITION:
            return self.streams.send_now(mav.MAVLINK_MSG_ID_HOME_POSITION)
        return mav.MAV_RESULT_UNSUPPORTED
