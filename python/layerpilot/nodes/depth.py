"""The depth node: camera frames in, map-frame point clouds out (stereo, or the frame's own depth).

It also listens to the vehicle's pose stream: the depth service learns the camera clock's offset
from it and reads the refinement's priors there. Poses are queued by the subscriber and handed
to the service by the worker before each frame, so that one thread touches the service.
"""

from __future__ import annotations

import logging
from collections import deque

import zenoh

from layerpilot.bus import keys
from layerpilot.bus.guard import guarded
from layerpilot.bus.messages import CloudMessage, FrameMessage, State, decode_frame, decode_state, encode_cloud
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.bus.session import publish
from layerpilot.mission.pipeline import MissionPipeline
from layerpilot.missionfile import Mission
from layerpilot.nodes.queue import DropOldest
from layerpilot.nodes.supervise import Supervisor

_log = logging.getLogger("layerpilot.depth")
POSE_BACKLOG = 2000  # poses kept between two frames (100 s of a 20 Hz stream)


class DepthNode:
    """The mission's DepthService on the bus: the node only decodes frames and publishes clouds."""

    def __init__(self, session: zenoh.Session, vehicle: str, mission: Mission,
                 supervisor: Supervisor | None = None) -> None:
        self.session, self.keys, self.cfg = session, keys.Keys(vehicle), mission.depth
        self.supervisor = supervisor or Supervisor(_log)
        self.rejects = Rejects(_log)
        self.queue: DropOldest[FrameMessage] = DropOldest(self.cfg.queue_size)
        self.pipeline = MissionPipeline(mission.core, {"depth"}, [vehicle])
        self.service = self.pipeline.depth[vehicle]
        self.poses: deque[State] = deque(maxlen=POSE_BACKLOG)  # appended by Zenoh's thread, drained by the worker
        self._subs: list = []
        self._status: dict = {}  # the service's stats after the last frame (written by the worker only)

    @property
    def clouds(self) -> int:
        return self.service.clouds

    def status(self) -> dict:
        """The service's counts after the last frame: frames, clouds, pairs, skips and the refinement's
        statistics (pairs refined, rejected by reason, the camera clock's offset)."""
        return dict(self._status)

    def start(self) -> None:
        self._subs = [
            self.session.declare_subscriber(self.keys.camera, guarded(decode_frame, lambda f, k: self.queue.put(f),
                                                                      self.rejects, self.supervisor)),
            self.session.declare_subscriber(self.keys.pose, guarded(decode_state, lambda s, k: self.poses.append(s),
                                                                    self.rejects, self.supervisor))]
        self.supervisor.start("depth", self._iteration)

    def stop(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self.queue.close()
        self.supervisor.join()

    def _iteration(self) -> bool:
        if (frame := self.queue.get(timeout=0.5)) is None:
            return not self.queue.closed
        while self.poses:
            state = self.poses.popleft()
            try:
                self.pipeline.telemetry(self.keys.vehicle, state.stamp, state.pose)
            except ValueError as exc:
                self.rejects.reject(self.keys.pose, BadMessage("bad pose", str(exc)))
        try:
            cloud = self.pipeline.frame(self.keys.vehicle, frame.frame)
        except ValueError as exc:  # the frame's fault (shape, pose): rejected with the reason
            self.rejects.reject(self.keys.camera, BadMessage("bad frame", str(exc)))
            return True
        finally:
            self._status = self.service.stats()
        if cloud is not None:
            publish(self.session, self.keys.cloud, encode_cloud(CloudMessage(
                self.keys.vehicle, frame.seq, cloud, self.cfg.max_depth)))
        return True
