"""Key names on the bus: everything of one vehicle lives under ``layerpilot/<vehicle>/``."""

from __future__ import annotations

import re
from dataclasses import dataclass

PREFIX = "layerpilot"
TOPICS = ("camera", "cloud", "pose", "layers", "decision", "waypoint", "state")
SERVICES = ("layers", "stats", "save", "voxels", "octree")
NODES = ("sim", "camera", "link", "depth", "decide", "ros2", "map-server")  # whose status goes out on health/<node>
_NAME = re.compile(r"^[A-Za-z0-9_\-]+$")


def check_vehicle(name: str) -> str:
    """Vehicle names become one key chunk: no '/', '*', '$', '?', '#' or spaces."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"vehicle: must be letters, digits, '_' or '-', got {name!r}")
    return name


@dataclass(frozen=True)
class Keys:
    """The keys of one vehicle (``Keys("uav1").cloud == "layerpilot/uav1/cloud"``)."""

    vehicle: str

    def __post_init__(self) -> None:
        check_vehicle(self.vehicle)

    def topic(self, name: str) -> str:
        if name not in TOPICS:
            raise ValueError(f"topic: unknown {name!r}; known: {', '.join(TOPICS)}")
        return f"{PREFIX}/{self.vehicle}/{name}"

    def service(self, name: str) -> str:
        if name not in SERVICES:
            raise ValueError(f"service: unknown {name!r}; known: {', '.join(SERVICES)}")
        return f"{PREFIX}/{self.vehicle}/map/{name}"

    def health(self, node: str) -> str:
        """A node's periodic status (``layerpilot/uav1/health/decide``); the map server has one per vehicle."""
        if node not in NODES:
            raise ValueError(f"health: unknown node {node!r}; known: {', '.join(NODES)}")
        return f"{PREFIX}/{self.vehicle}/health/{node}"

    @property
    def aggregates(self) -> str:
        """The decide node's queryable: A0..A3 of its last tick (asked by a viewer; nothing is sent otherwise)."""
        return f"{PREFIX}/{self.vehicle}/decide/aggregates"

    camera = property(lambda self: self.topic("camera"))
    cloud = property(lambda self: self.topic("cloud"))
    pose = property(lambda self: self.topic("pose"))
    layers = property(lambda self: self.topic("layers"))
    decision = property(lambda self: self.topic("decision"))
    waypoint = property(lambda self: self.topic("waypoint"))
    state = property(lambda self: self.topic("state"))


def all_vehicles(topic: str) -> str:
    """Key expression matching ``topic`` of every vehicle (a shared map server subscribes to this)."""
    if topic not in TOPICS:
        raise ValueError(f"topic: unknown {topic!r}; known: {', '.join(TOPICS)}")
    return f"{PREFIX}/*/{topic}"


def vehicle_of(key: str) -> str:
    """The vehicle chunk of a concrete key ``layerpilot/<vehicle>/...``."""
    parts = str(key).split("/")
    if len(parts) < 3 or parts[0] != PREFIX:
        raise ValueError(f"key: not under {PREFIX}/<vehicle>/: {key!r}")
    return parts[1]
