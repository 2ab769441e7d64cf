"""Publishing as a ROS 2 node does over rmw_zenoh, with nothing of ROS installed.

rmw_zenoh (ROS 2's Zenoh middleware; its docs/design.md and src/detail/liveliness_utils.cpp) maps a
topic to the key expression ``<domain_id>/<topic without its leading '/'>/<DDS type name>/<type hash>``
and announces every node and publisher with a liveliness token under ``@ros2_lv``:

    @ros2_lv/<domain>/<session id>/<node id>/<node id>/NN/<enclave>/<namespace>/<node name>
    @ros2_lv/<domain>/<session id>/<node id>/<entity id>/MP/<enclave>/<namespace>/<node name>/<topic>/<type>/<hash>/<qos>

with every ``/`` inside a name written ``%`` (``/`` alone is ``%``). ``ros2 topic list`` and
``ros2 topic echo`` read those tokens. Each sample carries the attachment rmw_zenoh requires, its
zenoh-ext serialization of (sequence number: int64, source timestamp in ns: int64, the publisher's
16-byte GID). rmw_zenoh derives a GID by hashing the token; any 16 stable bytes serve, here BLAKE2b's.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from itertools import count

import zenoh
from zenoh.ext import Int64, UInt8, z_serialize

from layerpilot.ros2.messages import RosType, serialize

ADMIN_SPACE = "@ros2_lv"
# the publishers' QoS as rmw_zenoh writes it against its defaults (reliable, transient local, keep last 42):
# durability volatile (2), keep last 10; deadline, lifespan and liveliness at their defaults
QOS = ":2:,10:,:,:,,"


def mangle(name: str) -> str:
    """A ROS name as one key chunk: every ``/`` becomes ``%``."""
    return name.replace("/", "%")


def topic_key(domain_id: int, topic: str, ros_type: RosType) -> str:
    """Where rmw_zenoh publishes ``topic`` of ``ros_type``: ``0/layerpilot/uav1/pose/geometry_msgs::...``."""
    return f"{domain_id}/{topic.strip('/')}/{ros_type.dds_name}/{ros_type.hash}"


def attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """The attachment every rmw_zenoh sample carries."""
    if len(gid) != 16:
        raise ValueError(f"gid: expected 16 bytes, got {len(gid)}")
    return z_serialize((Int64(sequence_number), Int64(source_timestamp_ns),
                        tuple(UInt8(b) for b in gid))).to_bytes()


@dataclass(frozen=True)
class RosNodeName:
    domain_id: int
    namespace: str  # "/" or "/layerpilot"
    name: str  # a ROS node name: letters, digits, '_'
    enclave: str = "/"


class RmwZenohPublisher:
    """One topic of one type; ``publish(message)`` serializes to CDR and puts it with its attachment."""

    def __init__(self, session: zenoh.Session, key: str, token_key: str) -> None:
        self.session, self.key = session, key
        self.gid = hashlib.blake2b(token_key.encode(), digest_size=16).digest()
        self._token = session.liveliness().declare_token(token_key)
        self._sequence = count(1)
        self.published = 0

    def publish(self, message: object, type_name: str) -> None:
        self.put(serialize(message, type_name))

    def put(self, cdr: bytes) -> None:
        # a put on the session, not a declared Zenoh publisher: behind the hub's allow-list a client is not told
        # of the subscribers, and a publisher puts nothing until it knows of one
        self.session.put(self.key, cdr, attachment=attachment(next(self._sequence), time.time_ns(), self.gid))
        self.published += 1

    def undeclare(self) -> None:
        self._token.undeclare()


class RmwZenohNode:
    """A ROS 2 node as rmw_zenoh announces it: its liveliness token, then one per publisher."""

    def __init__(self, session: zenoh.Session, node: RosNodeName) -> None:
        self.session, self.node = session, node
        self.zid = str(session.zid())
        self._ids = count(1)  # entity ids after the node's own 0, as rmw_zenoh numbers them per context
        self._base = (f"{ADMIN_SPACE}/{node.domain_id}/{self.zid}/0")
        self._names = f"{mangle(node.enclave)}/{mangle(node.namespace)}/{node.name}"
        self._token = session.liveliness().declare_token(f"{self._base}/0/NN/{self._names}")
        self.publishers: dict[str, RmwZenohPublisher] = {}

    def publisher(self, topic: str, ros_type: RosType) -> RmwZenohPublisher:
        """The publisher of ``topic`` (declared and announced at its first use)."""
        if topic not in self.publishers:
            token = (f"{self._base}/{next(self._ids)}/MP/{self._names}/{mangle(topic)}/{ros_type.dds_name}/"
                     f"{ros_type.hash}/{QOS}")
            self.publishers[topic] = RmwZenohPublisher(self.session, topic_key(self.node.domain_id, topic, ros_type),
                                                       token)
        return self.publishers[topic]

    def close(self) -> None:
        for p in self.publishers.values():
            p.undeclare()
        self._token.undeclare()
