"""The ROS 2 bridge node: one vehicle's pose, path, target, clouds and layers as rmw_zenoh topics.

It listens on the vehicle's bus keys, hands each payload to one worker (a queue that drops its
oldest, counted: a ROS 2 viewer wants the newest), translates it (ros2.topics) and publishes it
where ROS 2 nodes running rmw_zenoh on the same Zenoh network see it. Every ``octomap_period`` seconds
a second loop asks the map server for the whole map (``map/octree``, a ``.bt`` stream) and publishes it
as an octomap. Nothing of ROS is installed.
"""

from __future__ import annotations

import logging
import threading
import time

import zenoh

from layerpilot.bus import keys
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.nodes.queue import DropOldest
from layerpilot.nodes.supervise import Supervisor
from layerpilot.ros2.rmw_zenoh import RmwZenohNode, RosNodeName
from layerpilot.ros2.topics import Ros2Config, Ros2Topics, ros_vehicle

_log = logging.getLogger("layerpilot.ros2")
QUEUE = 16  # payloads waiting for the worker (a layer set and a cloud a second, with room for bursts)


class Ros2Bridge:
    def __init__(self, session: zenoh.Session, vehicle: str, cfg: Ros2Config,
                 supervisor: Supervisor | None = None) -> None:
        self.session, self.keys, self.cfg = session, keys.Keys(vehicle), cfg
        self.supervisor = supervisor or Supervisor(_log)
        self.rejects = Rejects(_log)
        self.topics = Ros2Topics(cfg)
        self.queue: DropOldest[tuple[str, str, bytes]] = DropOldest(QUEUE)
        self.node = RmwZenohNode(session, RosNodeName(cfg.domain_id, cfg.namespace,
                                                      f"{ros_vehicle(vehicle)}_bridge"))
        self._subs: list = []
        self._stop = threading.Event()
        self._stamp = 0.0  # the newest mission-clock stamp translated: the octomap's
        self._octree_due = 0.0  # monotonic time of the next map/octree query
        self.octree_failed = 0  # queries unanswered or answered with an error

    def start(self) -> None:
        # every publisher announced before the first message: ROS 2 tools list the topics from the start
        for topic, ros_type in self.topics.outputs(self.keys.vehicle):
            self.node.publisher(topic, ros_type)
        for topic in Ros2Topics.BUS_TOPICS:
            key = self.keys.topic(topic)
            self._subs.append(self.session.declare_subscriber(key, self._callback(key, topic)))
        self.supervisor.start("ros2", self._iteration)
        if self.cfg.octomap_period:
            self.supervisor.start("ros2-octomap", self._octomap_iteration)

    def _callback(self, key: str, topic: str):
        def on_sample(sample: zenoh.Sample) -> None:
            self.supervisor.heard(key)
            self.queue.put((key, topic, sample.payload.to_bytes()))
        return on_sample

    def _iteration(self) -> bool:
        if (item := self.queue.get(timeout=0.5)) is None:
            return not self.queue.closed
        key, topic, payload = item
        try:
            messages = self.topics.translate(topic, payload)
        except BadMessage as exc:
            self.rejects.reject(key, exc)
            return True
        for m in messages:
            self._stamp = max(self._stamp, m.stamp)
            self.node.publisher(m.topic, m.type).publish(m.message, m.type.name)
        return True

    def _octomap_iteration(self) -> bool:
        if self._stop.wait(min(0.5, max(0.0, self._octree_due - time.monotonic()))):
            return False
        if time.monotonic() < self._octree_due:
            return True
        self._octree_due = time.monotonic() + self.cfg.octomap_period
        key = self.keys.service("octree")
        replies = list(self.session.get(key, timeout=5.0))
        if not replies or replies[0].ok is None:
            self.octree_failed += 1
            return True
        try:
            m = self.topics.octomap(self.keys.vehicle, self._stamp, replies[0].ok.payload.to_bytes())
        except BadMessage as exc:
            self.rejects.reject(key, exc)
            return True
        self.node.publisher(m.topic, m.type).publish(m.message, m.type.name)
        return True

    def status(self) -> dict:
        return {"received": self.queue.received, "dropped": self.queue.dropped, "rejected": self.rejects.total,
                "octree_failed": self.octree_failed,
                "published": {topic: p.published for topic, p in self.node.publishers.items()}}

    def stop(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self.queue.close()
        self._stop.set()
        self.supervisor.join()
        self.node.close()
