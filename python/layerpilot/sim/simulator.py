"""The whole simulator: world + camera renderer + MAVLink multicopter, in lock-step or paced to real time.

Lock-step (tests, evaluation)::

    with Simulator(SimConfig(urls=("tcp:127.0.0.1:0",))) as sim:
        for _ in range(500):
            shot = sim.step()          # advances the mission clock by config.step_s
            if shot is not None:       # a camera frame is due every 1 / frame_rate_hz seconds
                stamp, frame = shot    # the frame's stamp (s) and the CameraFrame the drone delivers
        capture = sim.capture()        # or a frame now: .frame (delivered) and .truth (for scoring only)

Sensors (``SimConfig.sensors``, docs/sim.md): with ``perfect`` a frame is the rendered view at the
vehicle's pose, stamped with its time. Otherwise the camera renders at the TRUE pose, then
degrades the image (sensor profile); the frame is stamped on the camera's clock and carries the
pose the autopilot REPORTS at that stamp, as a camera node looking it up would find it.

Process (``layerpilot sim``): :meth:`Simulator.run` paces the same steps to the
wall clock (``speed`` times faster when > 1) and hands every frame to a callback.
The vehicle takes off from the origin, on the terrain at the launch clearing.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from layerpilot.config import check_range
from layerpilot.geometry import CameraFrame, Pose
from layerpilot.sim.battery import BatteryConfig
from layerpilot.camera import CameraConfig, camera_pose
from layerpilot.sim.sensors import SensorProfile, sensor_profile
from layerpilot.sim.world import World, WorldConfig


@dataclass(frozen=True)
class SimConfig:
    """World, camera, frame rate (mission Hz), MAVLink URLs, the autopilot flavour, its battery, and the
    sensors: a preset of :data:`layerpilot.sim.sensors.PROFILES` with single fields overridden."""

    world: WorldConfig = field(default_factory=WorldConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    frame_rate_hz: float = 5.0
    step_s: float = 0.02
    urls: tuple[str, ...] = ("tcp:127.0.0.1:5760",)
    flavour: str = "ardupilot"
    battery: BatteryConfig = field(default_factory=BatteryConfig)
    sensors: str = "perfect"
    sensor_overrides: dict[str, float] = field(default_factory=dict)
    sensor_seed: int | None = None  # the sensors' errors' seed (None: the world's); a fleet's drones differ

    def __post_init__(self) -> None:
        sensor_profile(self.sensors, self.sensor_overrides, "sim.")  # an unknown name or key is an error here
        check_range("frame_rate_hz", self.frame_rate_hz, 0.01, 100.0)
        check_range("step_s", self.step_s, 1e-4, 0.5)
        if self.flavour not in ("ardupilot", "px4"):
            raise ValueError(f"flavour: expected 'ardupilot' or 'px4', got {self.flavour!r}")

    @property
    def sensor_profile(self) -> SensorProfile:
        return sensor_profile(self.sensors, self.sensor_overrides)


@dataclass(frozen=True)
class Capture:
    """One exposure: ``frame`` is what the drone delivers (image, stamp, reported pose); ``truth`` the same
    exposure as it was (clean image, true camera pose and depth, stamped with the true time), for scoring only."""

    frame: CameraFrame
    truth: CameraFrame


def _tilt(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """The map-frame rotation of a roll (about the heading) and a nose-up pitch on a vehicle heading ``yaw``."""
    def axis(u: np.ndarray, a: float) -> np.ndarray:
        k = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
        return np.eye(3) + math.sin(a) * k + (1.0 - math.cos(a)) * k @ k

    forward = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    left = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    return axis(forward, roll) @ axis(left, -pitch)


class Simulator:
    """Owns the world, the renderer and the MAVLink vehicle endpoint; close() releases sockets and GL."""

    def __init__(self, config: SimConfig | None = None) -> None:
        from layerpilot.sim.camera_errors import CameraErrors
        from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
        from layerpilot.sim.render import Renderer
        from layerpilot.sim.vehicle import Multicopter

        self.config = config or SimConfig()
        self.world = World(self.config.world)
        ground = float(self.world.terrain_height(0.0, 0.0))
        self.vehicle = Multicopter(position=(0.0, 0.0, ground), ground_z=ground)
        self.sensors = self.config.sensor_profile
        seed = self.config.world.seed if self.config.sensor_seed is None else self.config.sensor_seed
        self.endpoint = MavlinkVehicle(self.vehicle, self.config.urls,
                                       EndpointConfig(flavour=self.config.flavour, battery=self.config.battery,
                                                      sensors=self.sensors, seed=seed))
        try:
            self.renderer = Renderer(self.world, self.config.camera)
        except Exception:
            self.endpoint.close()
            raise
        self.camera = None if self.sensors.exact_camera else CameraErrors(self.sensors, self.renderer.intrinsics, seed)
        self._next_frame = 0.0
        self.frames = 0

    @property
    def time(self) -> float:
        return self.endpoint.time

    def step(self):
        """One vehicle step; returns (stamp, CameraFrame) when a camera frame is due, else None."""
        self.endpoint.step(self.config.step_s)
        if self.endpoint.time + 1e-9 < self._next_frame:
            return None
        self._next_frame += 1.0 / self.config.frame_rate_hz
        self.frames += 1
        frame = self.capture().frame
        return frame.stamp, frame

    def capture(self, now: float | None = None) -> Capture:
        """Expose the camera now. ``now``: the time the stamps count from (default the endpoint's clock; the
        evaluator's mission clock starts after take-off)."""
        vehicle = self.endpoint.pose()
        now = vehicle.time if now is None else now
        if self.sensors.exact_pose and self.camera is None:
            frame = self.renderer.render_vehicle(vehicle.position, vehicle.yaw, now)
            return Capture(frame, frame)
        pitch = self.config.camera.pitch_deg
        nominal = camera_pose(vehicle.position, vehicle.yaw, pitch)
        if not self.sensors.exact_pose:  # the gimbal levels the camera on the EKF's horizon: the truth tilts
            error = self.endpoint.estimator.errors.current
            tilt = _tilt(error.roll, error.pitch, vehicle.yaw).T
            nominal = Pose.from_rotation(tilt @ nominal.rotation, nominal.position)
        truth = self.renderer.render(nominal, now)
        delay = 0.0 if self.camera is None else self.camera.stamp_error()
        image = truth.image if self.camera is None else self.camera.degrade(truth, vehicle.velocity,
                                                                            self.vehicle.yaw_rate)
        reported = self.endpoint.reported_pose_at(vehicle.time + delay)
        frame = CameraFrame(image, camera_pose(reported.position, reported.yaw, pitch), truth.intrinsics,
                            now + delay, truth.depth)
        return Capture(frame, truth)

    def run(self, on_frame: Callable[[float, object], None] | None = None, speed: float = 1.0,
            duration: float | None = None, stop: threading.Event | None = None) -> None:
        """Step paced to the wall clock until ``stop`` is set or ``duration`` mission seconds have passed.

        Frames are rendered at their mission times; if rendering is slower than
        the pace, the mission clock falls behind the wall clock rather than
        dropping frames, so a run is the same at any speed.
        """
        check_range("speed", speed, 1e-3, None)
        stop = stop or threading.Event()
        wall0, sim0 = time.monotonic(), self.time
        while not stop.is_set() and (duration is None or self.time < sim0 + duration - 1e-9):
            if self.time + self.config.step_s > sim0 + (time.monotonic() - wall0) * speed:
                stop.wait(min(0.005, self.config.step_s / speed))
                continue
            shot = self.step()
            if shot is not None and on_frame is not None:
                on_frame(*shot)

    def close(self) -> None:
        self.endpoint.stop()
        self.renderer.close()

    def __enter__(self) -> "Simulator":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
