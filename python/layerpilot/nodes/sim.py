"""The simulator node: renders the camera at the simulated vehicle's pose and publishes frames;
the simulated multicopter serves MAVLink on the configured URLs for the link node."""

from __future__ import annotations

import logging
import threading

import zenoh

from layerpilot.bus import keys
from layerpilot.bus.messages import Frame, encode_frame, quat_from_matrix

_log = logging.getLogger("layerpilot.sim")


class SimNode:
    def __init__(self, session: zenoh.Session, vehicle: str, sim_config, *, speed: float = 1.0,
                 publish_depth: bool = True) -> None:
        from layerpilot.sim.simulator import Simulator

        self.session, self.keys = session, keys.Keys(vehicle)
        self.sim = Simulator(sim_config)
        self.speed = speed
        self.publish_depth = publish_depth
        self.frames = 0

    def _on_frame(self, stamp: float, rendered) -> None:
        fx, fy, cx, cy = rendered.K[0, 0], rendered.K[1, 1], rendered.K[0, 2], rendered.K[1, 2]
        self.frames += 1
        self.session.put(self.keys.camera, encode_frame(Frame(
            stamp, self.keys.vehicle, self.frames, rendered.color, (fx, fy, cx, cy), rendered.pose.centre,
            quat_from_matrix(rendered.pose.rotation), rendered.depth if self.publish_depth else None)))

    def run(self, stop: threading.Event) -> None:
        """Step the simulator paced to the wall clock until ``stop`` (SIGTERM) is set."""
        try:
            self.sim.run(self._on_frame, speed=self.speed, stop=stop)
        finally:
            self.sim.close()
