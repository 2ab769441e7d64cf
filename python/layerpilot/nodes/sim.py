"""The simulator node: renders the camera at the simulated vehicle's pose and publishes frames;
the simulated multicopter serves MAVLink on the configured URLs for the link node. With a sensor
profile (``sim.sensors``) the frames are what the drone delivers: the degraded image, stamped on
the camera's clock, with the pose the autopilot reports (docs/sim.md)."""

from __future__ import annotations

import logging
import math
import threading

import dataclasses

import numpy as np
import zenoh

from layerpilot.bus import keys
from layerpilot.bus.guard import guarded
from layerpilot.bus.messages import FrameMessage, State, decode_state, encode_frame
from layerpilot.bus.reject import Rejects
from layerpilot.bus.session import publish
from layerpilot.geometry import CameraFrame, Pose
from layerpilot.mission.clock import MissionClock
from layerpilot.nodes.queue import DropOldest
from layerpilot.nodes.runner import WAKE_PERIOD

_log = logging.getLogger("layerpilot.sim")


def publish_frame(session: zenoh.Session, k: keys.Keys, seq: int, frame: CameraFrame, with_depth: bool,
                  lift: float = 0.0) -> None:
    """Put a rendered frame on the vehicle's camera key.

    ``lift``: metres the world's frame lies above the map frame (subtracted from the camera position).
    """
    frame = dataclasses.replace(frame.seen_from((0.0, 0.0, lift)), depth=frame.depth if with_depth else None)
    publish(session, k.camera, encode_frame(FrameMessage(k.vehicle, seq, frame)))


class SimNode:
    def __init__(self, session: zenoh.Session, vehicle: str, sim_config, *, speed: float = 1.0,
                 duration: float | None = None, publish_depth: bool = True,
                 clock: MissionClock = MissionClock()) -> None:
        """``clock``: the frames' stamps on the mission clock (the vehicle's clock + its start, mission.clock)."""
        from layerpilot.sim.simulator import Simulator

        self.session, self.keys = session, keys.Keys(vehicle)
        self.sim = Simulator(sim_config)
        self.speed, self.duration = speed, duration
        self.publish_depth = publish_depth
        self.clock = clock
        self.frames = 0

    def _on_frame(self, stamp: float, frame: CameraFrame) -> None:
        self.frames += 1
        # the link node publishes the vehicle's pose in its MAVLink local frame (z = 0 on the ground at home,
        # ArduCopter's EKF origin): the frames go out in that frame too, the mission's map frame
        frame = dataclasses.replace(frame, stamp=self.clock(frame.stamp))  # as the link node stamps the poses
        publish_frame(self.session, self.keys, self.frames, frame, self.publish_depth,
                      float(self.sim.endpoint.ekf_origin[2]))

    def describe(self) -> dict:
        """What a user needs to connect: the MAVLink addresses actually served (port 0 = a free one), the world."""
        c = self.sim.config
        return {"mavlink": [f"{u} -> {h}:{p}" for u, (h, p) in zip(c.urls, self.sim.endpoint.addresses)],
                "flavour": c.flavour, "seed": c.world.seed, "trees": self.sim.world.stats()["trees"],
                "camera": f"{c.camera.width}x{c.camera.height} at {c.frame_rate_hz:g} Hz",
                "renderer": self.sim.renderer.renderer_name, "speed": self.speed, "sensors": c.sensors}

    def run(self, stop: threading.Event) -> None:
        """Step the simulator paced to the wall clock until ``stop`` (SIGTERM) is set or ``duration`` has passed."""
        try:
            self.sim.run(self._on_frame, speed=self.speed, duration=self.duration, stop=stop)
        finally:
            self.sim.close()


class CameraOnlyNode:
    """Camera-only simulation: render layerpilot's world from the pose a real autopilot reports.

    The vehicle is someone else's (ArduPilot or PX4 SITL, flown by the link node); this node
    subscribes to its pose and publishes what the simulated camera would see, at most
    ``frame_rate_hz`` frames per mission second, like AirSim next to PX4/ArduPilot.
    A real autopilot's local frame has its origin at home, on the ground, so the pose is
    rendered ``lift`` metres higher in layerpilot's world (its terrain height at the
    origin) and the frames are published in the autopilot's frame, the mission's map frame.
    """

    def __init__(self, session: zenoh.Session, vehicle: str, sim_config) -> None:
        self.session, self.keys, self.config = session, keys.Keys(vehicle), sim_config
        self.rejects = Rejects(_log)
        self.queue: DropOldest[State] = DropOldest(1)  # only the newest pose matters
        self.frames = 0
        self._next = -math.inf
        self._sub = None

    def run(self, stop: threading.Event) -> None:
        """Render poses until ``stop``; the GL context belongs to the calling thread, so it is made here."""
        from layerpilot.sim.render import Renderer
        from layerpilot.sim.world import World

        world = World(self.config.world)
        lift = float(world.terrain_height(0.0, 0.0))
        renderer = Renderer(world, self.config.camera)
        self._sub = self.session.declare_subscriber(
            self.keys.pose, guarded(decode_state, lambda s, k: self.queue.put(s), self.rejects))
        try:
            while not stop.is_set():
                # the main thread: wake often, so that a SIGTERM caught by another thread is handled
                if (state := self.queue.get(timeout=WAKE_PERIOD)) is None or state.stamp < self._next:
                    continue
                self._next = state.stamp + 1.0 / self.config.frame_rate_hz
                frame = renderer.render_vehicle(state.pose.position + [0.0, 0.0, lift], state.pose.yaw, state.stamp)
                self.frames += 1
                publish_frame(self.session, self.keys, self.frames, frame, True, lift)
        finally:
            self._sub.undeclare()
            renderer.close()
