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
the map frame. The ENU/NED conversion (and the EKF origin's offset) is here and in
``link/`` only.

Sensors (``EndpointConfig.sensors``, a :class:`SensorProfile`): the vehicle flies its true
trajectory; every position and attitude it reports (GLOBAL_POSITION_INT, LOCAL_POSITION_NED,
ATTITUDE, GPS_RAW_INT) carries the EKF's error, and like a real autopilot it flies position
setpoints in its estimated frame (the true target is the commanded one minus the error, followed
as the error wanders). Home and the EKF origin are reported exact.

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

import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.config import check_range
from layerpilot.geodesy import LocalFrame
from layerpilot.link import modes
from layerpilot.link.frames import (enu_to_ned, local_ned_to_map, map_to_local_ned, ned_to_enu, yaw_enu_to_ned,
                                    yaw_ned_to_enu)
from layerpilot.link.mission_transfer import MissionItem
from layerpilot.sim.auto_mission import AutoMission
from layerpilot.sim.battery import Battery, BatteryConfig
from layerpilot.sim.estimate import Estimator, VehiclePose
from layerpilot.sim.mission_store import MESSAGES as MISSION_MESSAGES
from layerpilot.sim.mission_store import MissionStore
from layerpilot.sim.sensors import SensorProfile
from layerpilot.sim.vehicle import Multicopter
from layerpilot.sim.vehicle_transport import open_transport

DEFAULT_URL = "tcp:127.0.0.1:5760"
SITL_DATUM = LocalFrame(47.397742, 8.545594, 488.0)  # the PX4/ArduPilot SITL default field near Zurich
FORCE_DISARM_MAGIC = 21196  # ArduPilot/PX4: param2 of ARM_DISARM that forces a disarm in flight

POS_IGNORE = 0b111
VEL_IGNORE = 0b111000
YAW_IGNORE = 1024
YAW_RATE_IGNORE = 2048
GUIDED_VELOCITY_TIMEOUT_S = 3.0  # ArduCopter stops a velocity-only guided command after 3 s
LOOK_AT_MIN_DISTANCE_M = 2.0  # ArduCopter turns toward a guided destination only while farther than this

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

# EKF_STATUS_REPORT flags, after ArduCopter's estimator: without GPS attitude, vertical velocity
# and height in constant-position mode (0xA5 = 165); with a 3D fix and the origin set, attitude,
# velocities, relative and absolute horizontal position, absolute height and the predicted
# positions (0x33F = 831).
EKF_FLAGS_NO_GPS = (mav.EKF_ATTITUDE | mav.EKF_VELOCITY_VERT | mav.EKF_POS_VERT_ABS | mav.EKF_CONST_POS_MODE)
EKF_FLAGS_GOOD = (mav.EKF_ATTITUDE | mav.EKF_VELOCITY_HORIZ | mav.EKF_VELOCITY_VERT | mav.EKF_POS_HORIZ_REL
                  | mav.EKF_POS_HORIZ_ABS | mav.EKF_POS_VERT_ABS | mav.EKF_PRED_POS_HORIZ_REL
                  | mav.EKF_PRED_POS_HORIZ_ABS)

_SENSORS = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL | mav.MAV_SYS_STATUS_SENSOR_3D_MAG
            | mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE | mav.MAV_SYS_STATUS_SENSOR_GPS
            | mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL | mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
            | mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL | mav.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
            | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | mav.MAV_SYS_STATUS_AHRS | mav.MAV_SYS_STATUS_SENSOR_BATTERY)


@dataclass(frozen=True)
class EndpointConfig:
    """How the simulated autopilot behaves; times are mission seconds."""

    flavour: Literal["ardupilot", "px4"] = "ardupilot"
    origin: LocalFrame = SITL_DATUM   # where the map frame lies on the Earth (geodesy.LocalFrame)
    system_id: int = 1
    component_id: int = 1
    prearm_delay_s: float = 2.0        # GPS fix at half of it, pre-arm checks healthy after it
    auto_disarm_s: float = 10.0        # ArduCopter DISARM_DELAY / PX4 COM_DISARM_PRFLT
    rtl_alt_m: float = 15.0            # ArduCopter RTL_ALT (above home)
    land_speed_m_s: float = 0.5        # ArduCopter LAND_SPEED, below land_slow_below_m
    land_slow_below_m: float = 10.0
    offboard_loss_s: float = 1.0       # PX4 COM_OF_LOSS_T
    offboard_min_rate_hz: float = 2.0  # PX4 wants a setpoint stream faster than this before OFFBOARD
    battery: BatteryConfig = field(default_factory=BatteryConfig)  # SYS_STATUS, BATTERY_STATUS, failsafe
    sensors: SensorProfile = field(default_factory=SensorProfile)  # the EKF's errors (default: none)
    seed: int = 0                      # of the sensor errors' generator

    def __post_init__(self) -> None:
        if self.flavour not in (modes.ARDUPILOT, modes.PX4):
            raise ValueError(f"flavour: expected 'ardupilot' or 'px4', got {self.flavour!r}")
        check_range("system_id", self.system_id, 1, 255)
        check_range("component_id", self.component_id, 1, 255)
        for name in ("prearm_delay_s", "auto_disarm_s", "rtl_alt_m", "land_slow_below_m"):
            check_range(name, getattr(self, name), 0.0, None)
        for name in ("land_speed_m_s", "offboard_loss_s", "offboard_min_rate_hz"):
            check_range(name, getattr(self, name), 1e-6, None)


class _Broadcast:
    """File-like target of the pymavlink encoder: writes go to every transport unless paused."""

    def __init__(self, endpoint: MavlinkVehicle) -> None:
        self._endpoint = endpoint

    def write(self, data: bytes) -> None:
        if not self._endpoint.output_paused:
            for transport in self._endpoint._transports:
                transport.send(data)


class MavlinkVehicle:
    """A :class:`Multicopter` behind a MAVLink 2 autopilot interface (ArduCopter or PX4 conventions)."""

    def __init__(self, vehicle: Multicopter | None = None, urls: Sequence[str] | str = (DEFAULT_URL,),
                 config: EndpointConfig | None = None) -> None:
        self.vehicle = vehicle if vehicle is not None else Multicopter()
        self.config = config if config is not None else EndpointConfig()
        urls = [urls] if isinstance(urls, str) else list(urls)
        if not urls:
            raise ValueError("urls: give at least one tcp:/udpin:/udpout: URL")
        self._transports = []
        try:
            for url in urls:
                self._transports.append(open_transport(url))
        except OSError as exc:
            self.close()
            raise OSError(f"urls: cannot serve {url}: {exc}") from None
        self._mav = mav.MAVLink(_Broadcast(self), self.config.system_id, self.config.component_id)
        self._parsers: dict[tuple, mav.MAVLink] = {}
        self._lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.output_paused = False
        self.time = 0.0
        self.home = self.vehicle.position.copy()
        # the EKF origin: the first good position, on the ground at home (ArduCopter and PX4 alike)
        self.ekf_origin = np.array([self.home[0], self.home[1], self.vehicle.ground_z], dtype=float)
        self.armed = False
        self.flavour = self.config.flavour
        self.mode = "STABILIZE" if self.flavour == modes.ARDUPILOT else "POSCTL"
        self._intervals = self._default_intervals()
        self._next_send = {msg_id: 0.0 for msg_id in self._intervals}
        self.battery = Battery(self.config.battery)
        self.boots = 1
        self._battery_failsafe = False  # ArduCopter acts on the low-battery failsafe once per boot
        self._home_announced = False    # HOME_POSITION and GPS_GLOBAL_ORIGIN sent once when set, each boot
        self._boot_at = 0.0  # mission time of the last boot: time_boot_ms counts from here
        self._ground_time = 0.0
        self._airborne = False
        self._rtl_phase = ""
        self._velocity_deadline: float | None = None
        self._setpoint_times: list[float] = []
        self.messages_received = 0
        self.mission = MissionStore(self._mav)  # the mission protocol's vehicle side (upload, download)
        self._auto: AutoMission | None = None    # the stored mission's run in AUTO (ArduPilot flavour)
        self.estimator = Estimator(self.config.sensors, self.config.seed)
        self._exact_pose = self.config.sensors.exact_pose

    # --- public API ------------------------------------------------------------------
    @property
    def addresses(self) -> list[tuple[str, int]]:
        """Bound (host, port) of each transport, in the order of ``urls`` (useful with port 0)."""
        return [t.address for t in self._transports]

    @property
    def clients(self) -> int:
        return sum(t.peers for t in self._transports)

    def pose(self) -> VehiclePose:
        with self._lock:
            roll, pitch = self.vehicle.roll_pitch
            return VehiclePose(self.time, self.vehicle.position.copy(), self.vehicle.velocity.copy(),
                               roll, pitch, self.vehicle.yaw)

    def reported_pose(self) -> VehiclePose:
        """The state the autopilot reports (its EKF's estimate): :meth:`pose` plus the sensors' errors."""
        with self._lock:
            return self.pose() if self._exact_pose else self.estimator.report(self.pose())

    def reported_pose_at(self, t: float) -> VehiclePose:
        """The reported state at mission time ``t`` (within the last few seconds), interpolated between reports."""
        with self._lock:
            pose = self.estimator.at(t)
            return self.pose() if pose is None else pose

    def pause_output(self) -> None:
        """Stop sending anything (the vehicle keeps flying and listening): a link loss seen from outside."""
        self.output_paused = True

    def resume_output(self) -> None:
        self.output_paused = False

    def reboot(self) -> None:
        """Restart the autopilot as a power cycle does: a new boot (time_boot_ms from 0, pre-arm checks and
        GPS fix again after ``prearm_delay_s``), disarmed on the ground at home in its first mode, message
        intervals back to their defaults (the ArduPilot flavour forgets every stream asked of it, as
        ArduCopter does). The sockets stay served (a radio or serial link sees the new
        boot; SITL's TCP clients would reconnect); the battery keeps its charge."""
        with self._lock:
            self.boots += 1
            self._boot_at = self.time
            v = self.vehicle
            v.position[:] = (self.home[0], self.home[1], v.ground_z)
            v.velocity[:], v.acceleration[:], v.yaw_rate = 0.0, 0.0, 0.0
            self._set_disarmed("")
            v.hold()
            self.mode = "STABILIZE" if self.flavour == modes.ARDUPILOT else "POSCTL"
            self._velocity_deadline, self._setpoint_times = None, []
            self._auto = None  # a mission flown after the boot starts again at item 1
            self._battery_failsafe, self._home_announced = False, False
            self._intervals = self._default_intervals()
            self._next_send = {msg_id: self.time for msg_id in self._intervals}

    @property
    def uptime(self) -> float:
        """Seconds since the autopilot booted (its time_boot_ms)."""
        return self.time - self._boot_at

    def step(self, dt: float) -> None:
        """Handle what arrived, advance the mission clock by ``dt`` seconds, send what is due."""
        with self._lock:
            self._poll()
            self.time += dt
            self._update_modes()
            self.vehicle.step(dt)
            drift = self.estimator.errors.current.drift
            self.estimator.step(dt, self.pose())
            if self._airborne and not self._exact_pose:  # in the air it flies its estimate; on the ground it stays
                self.vehicle.shift_target(drift - self.estimator.errors.current.drift)
            self._after_motion(dt)
            self._send_due()

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
        for transport in self._transports:
            transport.close()
        self._transports = []

    def __enter__(self) -> MavlinkVehicle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # --- receiving -------------------------------------------------------------------
    def _poll(self) -> None:
        for transport in self._transports:
            for peer, data in list(transport.poll()):
                parser = self._parsers.get(peer)
                if parser is None:
                    parser = self._parsers[peer] = mav.MAVLink(None)
                    parser.robust_parsing = True
                for msg in parser.parse_buffer(data) or []:
                    if msg.get_type() != "BAD_DATA":
                        self.messages_received += 1
                        self._handle(msg)

    def _for_me(self, msg: mav.MAVLink_message) -> bool:
        ts, tc = getattr(msg, "target_system", 0), getattr(msg, "target_component", 0)
        return ts in (0, self.config.system_id) and tc in (0, self.config.component_id)

    def _handle(self, msg: mav.MAVLink_message) -> None:
        kind = msg.get_type()
        if kind in ("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT") and self._for_me(msg):
            self._setpoint(msg)
        elif kind == "COMMAND_LONG" and self._for_me(msg):
            result = self._command(msg)
            self._mav.command_ack_send(msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())
        elif kind == "REQUEST_DATA_STREAM" and self._for_me(msg) and self.flavour == modes.ARDUPILOT:
            self._request_data_stream(msg.req_stream_id, msg.req_message_rate if msg.start_stop else 0)
        elif kind in MISSION_MESSAGES and self._for_me(msg):
            self.mission.handle(msg)
        elif kind == "SET_MODE" and msg.target_system == self.config.system_id:
            result = self._set_mode_numbers(msg.base_mode, msg.custom_mode)
            self._mav.command_ack_send(mav.MAVLINK_MSG_ID_SET_MODE, result, 0, 0,
                                       msg.get_srcSystem(), msg.get_srcComponent())

    # --- commands --------------------------------------------------------------------
    @property
    def _refused(self) -> int:
        """The result code this autopilot uses for "not now" (ArduPilot FAILED, PX4 TEMPORARILY_REJECTED)."""
        return mav.MAV_RESULT_FAILED if self.flavour == modes.ARDUPILOT else mav.MAV_RESULT_TEMPORARILY_REJECTED

    def _command(self, msg: mav.MAVLink_message) -> int:
        c = msg.command
        if c == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            return self._arm(msg.param2 == FORCE_DISARM_MAGIC) if msg.param1 == 1 else \
                self._disarm(msg.param2 == FORCE_DISARM_MAGIC)
        if c == mav.MAV_CMD_DO_SET_MODE:
            if self.flavour == modes.PX4:
                return self._set_mode_numbers(int(msg.param1), modes.px4_custom_mode(int(msg.param2), int(msg.param3)))
            return self._set_mode_numbers(int(msg.param1), int(msg.param2))
        if c == mav.MAV_CMD_NAV_TAKEOFF:
            return self._takeoff(msg.param7)
        if c == mav.MAV_CMD_NAV_LAND:
            return self._enter_mode("LAND")
        if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self._enter_mode("RTL")
        if c == mav.MAV_CMD_DO_CHANGE_SPEED:
            return self._change_speed(msg.param2)
        if c == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_interval(int(msg.param1), msg.param2)
        if c == mav.MAV_CMD_REQUEST_MESSAGE:
            return self._send_now(int(msg.param1))
        if c == mav.MAV_CMD_GET_HOME_POSITION:
            return self._send_now(mav.MAVLINK_MSG_ID_HOME_POSITION)
        return mav.MAV_RESULT_UNSUPPORTED

    def _run_item(self, item: MissionItem) -> None:
        """A DO_* mission item, as its COMMAND_LONG (the mission store takes only DO_CHANGE_SPEED)."""
        if item.command == mav.MAV_CMD_DO_CHANGE_SPEED:
            self._change_speed(item.params[1])

    def _change_speed(self, speed: float) -> int:
        """DO_CHANGE_SPEED: a horizontal cruise speed up to the airframe's limit; -1 no change, -2 default."""
        if speed == -1.0:
            return mav.MAV_RESULT_ACCEPTED
        if speed == -2.0:
            self.vehicle.cruise_speed = None
            return mav.MAV_RESULT_ACCEPTED
        if not math.isfinite(speed) or speed <= 0.0:
            return mav.MAV_RESULT_DENIED
        self.vehicle.cruise_speed = min(float(speed), self.vehicle.limits.max_speed_h)
        return mav.MAV_RESULT_ACCEPTED

    def _prearm_ok(self) -> bool:
        return self.uptime >= self.config.prearm_delay_s

    def _arm(self, force: bool) -> int:
        if self.armed:
            return mav.MAV_RESULT_ACCEPTED
        if not self._prearm_ok() and not force:
            self._text(mav.MAV_SEVERITY_CRITICAL, "PreArm: Need Position Estimate" if self.flavour == modes.ARDUPILOT
                       else "Preflight Fail: No valid position estimate")
            return self._refused
        if self.mode in ("RTL", "LAND", "TAKEOFF", "AUTO"):  # AUTO: ArduCopter's default AUTO_OPTIONS 0
            self._text(mav.MAV_SEVERITY_CRITICAL, "Arm: Mode not armable" if self.flavour == modes.ARDUPILOT
                       else f"Arming denied: not in {self.mode}")
            return self._refused
        if self.mode == "OFFBOARD" and not self._setpoint_stream_ok():
            self._text(mav.MAV_SEVERITY_CRITICAL, "Arming denied: offboard signal lost")
            return self._refused
        self.armed, self.vehicle.motors_on = True, True
        self._ground_time = 0.0
        self.vehicle.hold()
        self._text(mav.MAV_SEVERITY_INFO,
                   "Arming motors" if self.flavour == modes.ARDUPILOT else "Armed by external command")
        return mav.MAV_RESULT_ACCEPTED

    def _disarm(self, force: bool) -> int:
        if self._airborne and not force:
            self._text(mav.MAV_SEVERITY_CRITICAL, "Disarm: vehicle is flying" if self.flavour == modes.ARDUPILOT
                       else "Disarming denied: not landed")
            return self._refused
        self._set_disarmed("Disarming motors")
        return mav.MAV_RESULT_ACCEPTED

    def _set_disarmed(self, reason: str) -> None:
        if self.armed and reason:
            self._text(mav.MAV_SEVERITY_INFO, reason)
        self.armed, self.vehicle.motors_on = False, False
        self._airborne = False
        self._rtl_phase = ""

    def _set_mode_numbers(self, base_mode: int, custom_mode: int) -> int:
        if not base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return mav.MAV_RESULT_UNSUPPORTED
        name = modes.mode_name(self.flavour, custom_mode)
        table = modes.COPTER_MODES if self.flavour == modes.ARDUPILOT else modes.PX4_MODES
        if name not in table:
            self._text(mav.MAV_SEVERITY_WARNING, f"Mode change to {name} failed: unsupported")
            return self._refused
        return self._enter_mode(name)

    def _enter_mode(self, name: str) -> int:
        if name == "OFFBOARD" and not self._setpoint_stream_ok():
            self._text(mav.MAV_SEVERITY_WARNING, "Switching to Offboard is currently not available")
            return self._refused
        if name == "TAKEOFF" and not self.armed:
            return self._refused
        if name == self.mode:
            return mav.MAV_RESULT_ACCEPTED
        if name == "AUTO" and (refusal := self._start_auto()) is not None:
            return refusal
        self.mode = name
        self._velocity_deadline = None
        self._rtl_phase = "climb" if name == "RTL" else ""
        if self.armed and name in ("GUIDED", "LOITER", "STABILIZE", "POSCTL", "OFFBOARD", "RTL", "LAND"):
            self.vehicle.hold()
        return mav.MAV_RESULT_ACCEPTED

    def _takeoff(self, param7: float) -> int:
        if not self.armed or self._airborne:
            return self._refused
        if self.flavour == modes.ARDUPILOT:
            if self.mode != "GUIDED" or not param7 > 0.0:
                return self._refused
            target_z = self.home[2] + param7
        else:
            target_z = self.home[2] + 2.5 if math.isnan(param7) else param7 - self.config.origin.alt
            self._enter_mode("TAKEOFF")
        self._airborne = True
        self.vehicle.set_position_target(z=self._true_target((0.0, 0.0, target_z))[2])  # climbs on its estimate
        return mav.MAV_RESULT_ACCEPTED

    def _default_intervals(self) -> dict[int, float]:
        """PX4 streams its set unasked; ArduCopter only HEARTBEAT until a stream is asked for."""
        if self.flavour == modes.PX4:
            return dict(DEFAULT_INTERVALS)
        return {msg_id: interval if msg_id == mav.MAVLINK_MSG_ID_HEARTBEAT else math.inf
                for msg_id, interval in DEFAULT_INTERVALS.items()}

    def _set_interval(self, msg_id: int, interval_us: float) -> int:
        if msg_id not in DEFAULT_INTERVALS:
            return mav.MAV_RESULT_FAILED
        if interval_us < 0:
            self._intervals[msg_id] = math.inf
        elif interval_us == 0:
            self._intervals[msg_id] = self._default_intervals()[msg_id]
        else:
            self._intervals[msg_id] = interval_us * 1e-6
        self._next_send[msg_id] = self.time
        return mav.MAV_RESULT_ACCEPTED

    def _request_data_stream(self, stream: int, rate_hz: float) -> None:
        """ArduPilot's REQUEST_DATA_STREAM: a group (or all, MAV_DATA_STREAM_ALL) at ``rate_hz``, 0 stops it."""
        groups = DATA_STREAMS.values() if stream == mav.MAV_DATA_STREAM_ALL else [DATA_STREAMS.get(stream, ())]
        for msg_id in (m for group in groups for m in group):
            self._intervals[msg_id] = 1.0 / rate_hz if rate_hz > 0 else math.inf
            self._next_send[msg_id] = self.time

    def _send_now(self, msg_id: int) -> int:
        if msg_id not in DEFAULT_INTERVALS:
            return mav.MAV_RESULT_UNSUPPORTED
        self._send(msg_id)
        return mav.MAV_RESULT_ACCEPTED

    # --- setpoints -------------------------------------------------------------------
    def _setpoint(self, msg: mav.MAVLink_message) -> None:
        self._setpoint_times = [t for t in self._setpoint_times if t > self.time - 1.0] + [self.time]
        follows = self.mode == "OFFBOARD" if self.flavour == modes.PX4 else (self.mode == "GUIDED" and self._airborne)
        if not follows or not self.armed:
            return
        mask = msg.type_mask
        position = velocity = None
        if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            position, velocity = self._local_target(msg)
        else:
            position, velocity = self._global_target(msg)
        if position is None and velocity is None:
            return
        yaw = None if mask & YAW_IGNORE else yaw_ned_to_enu(msg.yaw)
        if mask & POS_IGNORE != POS_IGNORE:
            if yaw is None and mask & YAW_RATE_IGNORE and self.flavour == modes.ARDUPILOT:
                yaw = self._look_at(position)
            self.vehicle.set_position_target(*position, yaw=yaw)
            self._velocity_deadline = None
            self._airborne = self._airborne or position[2] > self.vehicle.ground_z + 0.2
        elif mask & VEL_IGNORE != VEL_IGNORE:
            self.vehicle.set_velocity_target(*velocity, yaw=yaw)
            self._velocity_deadline = self.time + GUIDED_VELOCITY_TIMEOUT_S
            self._airborne = self._airborne or velocity[2] > 0.0
        else:
            self.vehicle.set_yaw_target(yaw=yaw)
        if yaw is None and not mask & YAW_RATE_IGNORE:
            self.vehicle.set_yaw_target(yaw_rate=-msg.yaw_rate)

    def _look_at(self, position) -> float | None:
        """ArduCopter's default WP_YAW_BEHAVIOR (2): face the destination while it is more than 2 m away."""
        dx, dy = position[0] - self.vehicle.position[0], position[1] - self.vehicle.position[1]
        return math.atan2(dy, dx) if math.hypot(dx, dy) > LOOK_AT_MIN_DISTANCE_M else None

    def _local_target(self, msg: mav.MAVLink_message) -> tuple[tuple | None, tuple | None]:
        frame = msg.coordinate_frame
        n, e, d = msg.x, msg.y, msg.z
        vn, ve, vd = msg.vx, msg.vy, msg.vz
        if frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED):
            heading = yaw_enu_to_ned(self.vehicle.yaw)
            c, s = math.cos(heading), math.sin(heading)
            n, e = c * n - s * e, s * n + c * e
            vn, ve = c * vn - s * ve, s * vn + c * ve
        elif frame not in (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_OFFSET_NED):
            self._text(mav.MAV_SEVERITY_WARNING, f"Unsupported setpoint frame {frame}")
            return None, None
        if frame == mav.MAV_FRAME_LOCAL_NED:
            position = self._true_target(local_ned_to_map(n, e, d, self.ekf_origin))   # relative to the EKF origin
        else:
            position = tuple(np.add(ned_to_enu(n, e, d), self.vehicle.position))
        return position, ned_to_enu(vn, ve, vd)

    def _global_target(self, msg: mav.MAVLink_message) -> tuple[tuple | None, tuple | None]:
        frame = msg.coordinate_frame
        home_amsl = self.config.origin.alt + self.home[2]
        if frame in (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT):
            alt = msg.alt
        elif frame in (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                       mav.MAV_FRAME_GLOBAL_TERRAIN_ALT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT):
            alt = home_amsl + msg.alt
        else:
            self._text(mav.MAV_SEVERITY_WARNING, f"Unsupported setpoint frame {frame}")
            return None, None
        x, y, z = self.config.origin.from_geodetic(msg.lat_int * 1e-7, msg.lon_int * 1e-7, alt)
        return self._true_target((float(x), float(y), float(z))), ned_to_enu(msg.vx, msg.vy, msg.vz)

    def _true_target(self, position: tuple) -> tuple:
        """Where the vehicle goes for a target in its estimated frame: the target minus the EKF's drift."""
        if self._exact_pose:
            return position
        return tuple(float(c) for c in np.subtract(position, self.estimator.errors.current.drift))

    def _setpoint_stream_ok(self) -> bool:
        """PX4's offboard condition: setpoints arriving faster than ``offboard_min_rate_hz`` right now."""
        recent = [t for t in self._setpoint_times if t > self.time - 1.0]
        return bool(recent) and self.time - recent[-1] <= 1.0 / self.config.offboard_min_rate_hz \
            and len(recent) >= self.config.offboard_min_rate_hz

    # --- mode behaviour --------------------------------------------------------------
    def _update_modes(self) -> None:
        v, cfg = self.vehicle, self.config
        if not self.armed:
            return
        if self.mode == "OFFBOARD" and (not self._setpoint_times or
                                        self.time - self._setpoint_times[-1] > cfg.offboard_loss_s):
            self._text(mav.MAV_SEVERITY_CRITICAL, "Failsafe: offboard signal lost, holding")
            self.mode = "LOITER"
            v.hold()
        if self.battery.low and self._airborne and not self._battery_failsafe and self.mode not in ("RTL", "LAND"):
            self._battery_failsafe = True  # BATT_FS_LOW_ACT = RTL, once: a pilot may then take another mode
            self._text(mav.MAV_SEVERITY_CRITICAL, f"Battery 1 is low {self.battery.voltage:.2f}V used "
                                                  f"{self.battery.consumed_mah:.0f} mAh")
            self._enter_mode("RTL")
        if self._velocity_deadline is not None and self.time > self._velocity_deadline:
            self._velocity_deadline = None
            v.hold()
        if self.mode == "TAKEOFF":
            target = v.position_target
            if target is not None and abs(v.position[2] - target[2]) < 0.3:
                self.mode = "LOITER"
        elif self.mode == "RTL" and self._airborne:
            self._update_rtl()
        elif self.mode == "LAND" and self._airborne:
            self._descend()
        elif self.mode == "AUTO":
            self._update_auto()

    def _start_auto(self) -> int | None:
        """ArduCopter's checks on entering AUTO; None when the mission starts (or resumes), else the refusal."""
        items = self.mission.items
        if len(items) <= 1:  # item 0 is home
            self._text(mav.MAV_SEVERITY_WARNING, "Mode change to AUTO failed: init failed")
            return self._refused
        if self.armed and not self._airborne and items[1].command != mav.MAV_CMD_NAV_TAKEOFF:
            self._text(mav.MAV_SEVERITY_CRITICAL, "Auto: Missing Takeoff Cmd")
            return self._refused
        if self._auto is None or self._auto.complete or self._auto.items is not items:
            self._auto = AutoMission(self._mav, items, self.config.origin, self.home, self._run_item)
        if self.armed:
            self._auto.resume(self.vehicle)
        return None

    def _update_auto(self) -> None:
        """Fly the mission; its LAND and RTL items use the endpoint's landing and return."""
        v = self.vehicle
        if not self._rtl_phase:
            action = self._auto.step(v, self.time)
            if action:
                self._rtl_phase = "climb" if action == "rtl" else "land"
            target = v.position_target
            self._airborne = self._airborne or (target is not None and target[2] > v.ground_z + 0.2)
        if self._rtl_phase and self._airborne:
            self._update_rtl()

    def _update_rtl(self) -> None:
        v, home = self.vehicle, self.home
        if self._rtl_phase == "climb":
            alt = max(v.position[2], home[2] + self.config.rtl_alt_m)
            v.set_position_target(v.position[0], v.position[1], alt)
            if v.position[2] >= alt - 0.3:
                self._rtl_phase = "return"
        if self._rtl_phase == "return":
            v.set_position_target(home[0], home[1])
            if np.hypot(*(v.position[:2] - home[:2])) < 0.5 and np.linalg.norm(v.velocity[:2]) < 0.3:
                self._rtl_phase = "land"
        if self._rtl_phase == "land":
            self._descend()

    def _descend(self) -> None:
        v, cfg = self.vehicle, self.config
        height = v.position[2] - v.ground_z
        speed = cfg.land_speed_m_s if height < cfg.land_slow_below_m else v.limits.max_speed_down
        v.set_velocity_target(0.0, 0.0, -speed)

    def _after_motion(self, dt: float) -> None:
        v = self.vehicle
        self.battery.drain(dt, self.armed)
        if not self.armed:
            return
        if self._airborne and v.on_ground and (self.mode == "LAND" or self._rtl_phase == "land"):
            self._set_disarmed("Land complete, disarming")
            return
        if v.on_ground and not (v.position_target is not None and v.position_target[2] > v.ground_z + 0.2):
            self._ground_time += dt
            if self._ground_time >= self.config.auto_disarm_s:
                self._set_disarmed("Disarming: landed" if self._airborne else "Disarming: auto disarm on ground")
        else:
            self._ground_time = 0.0

    # --- sending ---------------------------------------------------------------------
    def _text(self, severity: int, text: str) -> None:
        self._mav.statustext_send(severity, text[:50].encode())

    def _send_due(self) -> None:
        if not self._home_announced and self._has_fix():  # as ArduCopter when it sets home and the EKF origin
            self._home_announced = True
            self._send(mav.MAVLINK_MSG_ID_HOME_POSITION)
            self._send(mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        for msg_id, interval in self._intervals.items():
            if math.isfinite(interval) and self.time + 1e-9 >= self._next_send[msg_id] and self._send(msg_id):
                self._next_send[msg_id] = max(self._next_send[msg_id] + interval, self.time + 0.5 * interval)

    def _send(self, msg_id: int) -> bool:
        """Send message ``msg_id`` now; False when there is nothing to say yet (no position estimate)."""
        if msg_id in (mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                      mav.MAVLINK_MSG_ID_HOME_POSITION, mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN) and not self._has_fix():
            return False  # like an EKF without GPS: no origin, no home, no position yet
        if msg_id == mav.MAVLINK_MSG_ID_EKF_STATUS_REPORT and self.flavour != modes.ARDUPILOT:
            return True   # an ArduPilot message; PX4 reports its estimator otherwise
        getattr(self, "_send_" + mav.mavlink_map[msg_id].msgname.lower())()
        return True

    def _has_fix(self) -> bool:
        return self.uptime >= 0.5 * self.config.prearm_delay_s

    def _boot_ms(self) -> int:
        return int(self.uptime * 1000) & 0xFFFFFFFF

    def _send_heartbeat(self) -> None:
        base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mav.MAV_MODE_FLAG_STABILIZE_ENABLED
        if self.mode in ("GUIDED", "OFFBOARD", "RTL", "LAND", "LOITER", "TAKEOFF", "AUTO"):
            base |= mav.MAV_MODE_FLAG_GUIDED_ENABLED
        if self.armed:
            base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        autopilot = mav.MAV_AUTOPILOT_ARDUPILOTMEGA if self.flavour == modes.ARDUPILOT else mav.MAV_AUTOPILOT_PX4
        self._mav.heartbeat_send(mav.MAV_TYPE_QUADROTOR, autopilot, base,
                                 modes.custom_mode_of(self.flavour, self.mode),
                                 mav.MAV_STATE_ACTIVE if self.armed else mav.MAV_STATE_STANDBY)

    def _send_sys_status(self) -> None:
        present = _SENSORS | mav.MAV_SYS_STATUS_PREARM_CHECK
        health = _SENSORS if self._has_fix() else _SENSORS & ~mav.MAV_SYS_STATUS_SENSOR_GPS
        if self._prearm_ok():
            health |= mav.MAV_SYS_STATUS_PREARM_CHECK
        b = self.battery
        self._mav.sys_status_send(present, present, health, 200, int(b.voltage * 1000), int(b.current_a * 100),
                                  int(round(100 * b.remaining)), 0, 0, 0, 0, 0, 0)

    def _send_battery_status(self) -> None:
        """As ArduCopter sends it without cell monitoring: the pack voltage in the first cell, the others unknown."""
        b = self.battery
        cells = [min(int(b.voltage * 1000), 65534)] + [65535] * 9
        self._mav.battery_status_send(0, mav.MAV_BATTERY_FUNCTION_UNKNOWN, mav.MAV_BATTERY_TYPE_LIPO, 32767, cells,
                                      int(b.current_a * 100), int(b.consumed_mah), -1, int(round(100 * b.remaining)))

    def _send_mission_current(self) -> None:
        """As ArduPilot: the item flown and the mission's state; before any run item 0, NOT_STARTED
        (NO_MISSION without items); the total leaves out ArduPilot's home item."""
        if self._auto is not None and self._auto.items is self.mission.items:
            self._auto.send_current(self.mode == "AUTO")
            return
        total = max(len(self.mission.items) - (self.flavour == modes.ARDUPILOT), 0)
        self._mav.mission_current_send(0, total, mav.MISSION_STATE_NOT_STARTED if total else
                                       mav.MISSION_STATE_NO_MISSION, 0)

    def _send_system_time(self) -> None:
        self._mav.system_time_send(0, self._boot_ms())

    def _geodetic(self, point) -> tuple[int, int, int]:
        """A map-frame point as MAVLink's lat, lon (1e-7 degrees) and altitude AMSL (mm)."""
        lat, lon, alt = self.config.origin.to_geodetic(*point)
        return int(round(float(lat) * 1e7)), int(round(float(lon) * 1e7)), int(round(float(alt) * 1000))

    def _send_gps_raw_int(self) -> None:
        """The receiver's own fix: its error without the EKF's (no barometer, no white noise smoothing)."""
        gnss = 0.0 if self._exact_pose else self.estimator.errors.current.gnss
        lat, lon, alt = self._geodetic(self.vehicle.position + gnss)
        v = self.vehicle.velocity
        fix = mav.GPS_FIX_TYPE_3D_FIX if self._has_fix() else mav.GPS_FIX_TYPE_NO_FIX
        cog = int(math.degrees(math.atan2(v[0], v[1])) % 360 * 100) if np.hypot(v[0], v[1]) > 0.2 else 0xFFFF
        self._mav.gps_raw_int_send(int(self.uptime * 1e6), fix, lat, lon, alt, 80, 120,
                                   int(np.hypot(v[0], v[1]) * 100), cog, 14 if self._has_fix() else 3)

    def _send_global_position_int(self) -> None:
        reported = self.reported_pose()
        lat, lon, alt = self._geodetic(reported.position)
        vn, ve, vd = enu_to_ned(*reported.velocity)
        relative = int(round((reported.position[2] - self.home[2]) * 1000))
        hdg = int(round(math.degrees(yaw_enu_to_ned(reported.yaw)) % 360 * 100)) % 36000
        self._mav.global_position_int_send(self._boot_ms(), lat, lon, alt, relative, int(vn * 100), int(ve * 100),
                                           int(vd * 100), hdg)

    def _send_local_position_ned(self) -> None:
        reported = self.reported_pose()
        n, e, d = map_to_local_ned(*reported.position, self.ekf_origin)
        vn, ve, vd = enu_to_ned(*reported.velocity)
        self._mav.local_position_ned_send(self._boot_ms(), n, e, d, vn, ve, vd)

    def _send_attitude(self) -> None:
        reported = self.reported_pose()
        self._mav.attitude_send(self._boot_ms(), reported.roll, reported.pitch, yaw_enu_to_ned(reported.yaw), 0.0, 0.0,
                                -self.vehicle.yaw_rate)

    def _send_home_position(self) -> None:
        """Home's latitude, longitude and altitude AMSL (the world's datum plus the terrain height under home);
        its local position relative to the EKF origin, which is home on the ground: 0, 0, 0, what ArduPilot
        always sends there (should a test move ``home``, the endpoint sends the offset, which ArduPilot would not)."""
        n, e, d = map_to_local_ned(*self.home, self.ekf_origin)
        self._mav.home_position_send(*self._geodetic(self.home), n, e, d, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                                     int(self.uptime * 1e6))

    def _send_gps_global_origin(self) -> None:
        """The EKF origin's latitude, longitude and altitude AMSL (the local NED frame's 0, 0, 0)."""
        self._mav.gps_global_origin_send(*self._geodetic(self.ekf_origin), int(self.uptime * 1e6))

    def _send_ekf_status_report(self) -> None:
        if self._has_fix():
            self._mav.ekf_status_report_send(EKF_FLAGS_GOOD, 0.02, 0.01, 0.01, 0.02, 0.0)
        else:
            self._mav.ekf_status_report_send(EKF_FLAGS_NO_GPS, 0.0, 0.0, 0.0, 0.02, 0.0)
