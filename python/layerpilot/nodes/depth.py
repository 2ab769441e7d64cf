"""The depth node: camera frames in, map-frame point clouds out (stereo, or the frame's own depth)."""

from __future__ import annotations

import logging

import zenoh

from layerpilot.bus import keys
from layerpilot.bus.guard import guarded
from layerpilot.bus.messages import CloudMessage, FrameMessage, decode_frame, encode_cloud
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.bus.session import publish
from layerpilot.mission.build import build_depth_service
from layerpilot.mission.config import Mission
from layerpilot.nodes.queue import DropOldest
from layerpilot.nodes.supervise import Supervisor

_log = logging.getLogger("layerpilot.depth")


class DepthNode:
    """The mission's DepthService on the bus: the node only decodes frames and publishes clouds."""

    def __init__(self, session: zenoh.Session, vehicle: str, mission: Mission,
                 supervisor: Supervisor | None = None) -> None:
        self.session, self.keys, self.cfg = session, keys.Keys(vehicle), mission.depth
        self.supervisor = supervisor or Supervisor(_log)
        self.rejects = Rejects(_log)
        self.queue: DropOldest[FrameMessage] = DropOldest(self.cfg.queue_size)
        self.service = build_depth_service(mission)
        self._sub = None

    @property
    def clouds(self) -> int:
        return self.service.clouds

    def start(self) -> None:
        self._sub = self.session.declare_subscriber(self.keys.camera,
                                                    guarded(decode_frame, lambda f, k: self.queue.put(f), self.rejects,
                                                            self.supervisor))
        self.supervisor.start("depth", self._iteration)

    def stop(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
        self.queue.close()
        self.supervisor.join()

    def _iteration(self) -> bool:
        if (frame := self.queue.get(timeout=0.5)) is None:
            return not self.queue.closed
        try:
            cloud = self.service.push(frame.frame)
        except ValueError as exc:  # the frame's fault (shape, pose): rejected with the reason
            self.rejects.reject(self.keys.camera, BadMessage("bad frame", str(exc)))
            return True
        if cloud is not None:
            publish(self.session, self.keys.cloud, encode_cloud(CloudMessage(
                self.keys.vehicle, frame.seq, cloud, self.cfg.max_depth)))
        return True
