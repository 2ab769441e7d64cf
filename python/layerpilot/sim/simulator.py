"""The whole simulator: world + camera renderer + MAVLink multicopter, in lock-step or paced to real time.

Lock-step (tests, evaluation)::

    with Simulator(SimConfig(urls=("tcp:127.0.0.1:0",))) as sim:
        for _ in range(500):
            shot = sim.step()          # advances the mission clock by config.step_s
            if shot is not None:       # a camera frame is due every 1 / frame_rate_hz seconds
                stamp, frame = shot    # mission time (s), CameraFrame from the vehicle's pose (stamped)

Process (``layerpilot sim``): :meth:`Simulator.run` paces the same steps to the
wall clock (``speed`` times faster when > 1) and hands every frame to a callback.
The vehicle takes off from the origin, on the terrain at the launch clearing.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from layerpilot.config import check_range
from layerpilot.sim.battery import BatteryConfig
from layerpilot.sim.camera import CameraConfig
from layerpilot.sim.world import World, WorldConfig


@dataclass(frozen=True)
class SimConfig:
    """World, camera, frame rate (mission Hz), MAVLink URLs, the autopilot flavour and its battery."""

    world: WorldConfig = field(default_factory=WorldConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    frame_rate_hz: float = 5.0
    step_s: float = 0.02
    urls: tuple[str, ...] = ("tcp:127.0.0.1:5760",)
    flavour: str = "ardupilot"
    battery: BatteryConfig = field(default_factory=BatteryConfig)

    def __post_init__(self) -> None:
        check_range("frame_rate_hz", self.frame_rate_hz, 0.01, 100.0)
        check_range("step_s", self.step_s, 1e-4, 0.5)
        if self.flavour not in ("ardupilot", "px4"):
            raise ValueError(f"flavour: expected 'ardupilot' or 'px4', got {self.flavour!r}")


class Simulator:
    """Owns the world, the renderer and the MAVLink vehicle endpoint; close() releases sockets and GL."""

    def __init__(self, config: SimConfig | None = None) -> None:
        from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
        from layerpilot.sim.render import Renderer
        from layerpilot.sim.vehicle import Multicopter

        self.config = config or SimConfig()
        self.world = World(self.config.world)
        ground = float(self.world.terrain_height(0.0, 0.0))
        self.vehicle = Multicopter(position=(0.0, 0.0, ground), ground_z=ground)
        self.endpoint = MavlinkVehicle(self.vehicle, self.config.urls, EndpointConfig(flavour=self.config.flavour,
                                                                                    battery=self.config.battery))
        try:
            self.renderer = Renderer(self.world, self.config.camera)
        except Exception:
            self.endpoint.close()
            raise
        self._next_frame = 0.0
        self.frames = 0

    @property
    def time(self) -> float:
        return self.endpoint.time

    def step(self):
        """One vehicle step; returns (mission time, CameraFrame) when a camera frame is due, else None."""
        self.endpoint.step(self.config.step_s)
        if self.endpoint.time + 1e-9 < self._next_frame:
            return None
        self._next_frame += 1.0 / self.config.frame_rate_hz
        pose = self.endpoint.pose()
        self.frames += 1
        return pose.time, self.renderer.render_vehicle(pose.position, pose.yaw, pose.time)

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
