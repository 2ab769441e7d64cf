"""Which ROS 2 topics a bus message becomes: one translation for the live bridge and for recordings.

| bus key | ROS 2 topic | type |
|---|---|---|
| ``layerpilot/<v>/pose`` | ``<ns>/<v>/pose`` | geometry_msgs/msg/PoseStamped |
| ``layerpilot/<v>/pose`` | ``<ns>/<v>/path`` (at most ``path_rate`` Hz) | nav_msgs/msg/Path |
| ``layerpilot/<v>/decision`` | ``<ns>/<v>/target`` | geometry_msgs/msg/PoseStamped |
| ``layerpilot/<v>/cloud`` | ``<ns>/<v>/cloud`` | sensor_msgs/msg/PointCloud2 |
| ``layerpilot/<v>/layers`` | ``<ns>/<v>/map`` | nav_msgs/msg/OccupancyGrid |
| ``layerpilot/<v>/layers`` | ``<ns>/<v>/grid_map`` | grid_map_msgs/msg/GridMap |
| ``layerpilot/<v>/map/octree`` (asked every ``octomap_period`` s) | ``<ns>/<v>/octomap`` | octomap_msgs/msg/Octomap |

Vehicle names may hold ``-``, which ROS names may not: it becomes ``_``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from layerpilot.bus import messages as bus
from layerpilot.bus.layerset import decode_layer_set, to_column_layers
from layerpilot.bus.reject import BadMessage
from layerpilot.config import ConfigError, check_range
from layerpilot.geometry import Pose
from layerpilot.ros2 import messages as ros

_ROS_NAME = re.compile(r"^(/[A-Za-z][A-Za-z0-9_]*)+$")


@dataclass(frozen=True)
class Ros2Config:
    """The ``[ros2]`` table: the bridge's ROS 2 side (``layerpilot ros2``; `up` starts one per vehicle when
    ``enabled``)."""

    enabled: bool = False
    domain_id: int = 0  # ROS_DOMAIN_ID
    namespace: str = "/layerpilot"  # topics are <namespace>/<vehicle>/<name>
    path_rate: float = 1.0  # Hz at most of the flown path
    path_spacing: float = 1.0  # m between two kept poses of the path
    path_poses: int = 5000  # the path keeps its newest this many poses
    octomap_period: float = 10.0  # s between two octomap messages (the map server's whole map); 0 = none

    def __post_init__(self) -> None:
        check_range("ros2.domain_id", self.domain_id, 0, 232)  # ROS 2's usable domain ids
        if not _ROS_NAME.match(self.namespace):
            raise ConfigError(f"ros2.namespace: expected an absolute ROS name such as '/layerpilot', "
                              f"got {self.namespace!r}")
        check_range("ros2.path_rate", self.path_rate, 0.01, 100.0)
        check_range("ros2.path_spacing", self.path_spacing, 0.0, 1000.0)
        check_range("ros2.path_poses", self.path_poses, 2, 1_000_000)
        if self.octomap_period != 0:
            check_range("ros2.octomap_period", self.octomap_period, 1.0, 3600.0)


def ros_vehicle(vehicle: str) -> str:
    """A vehicle name as a ROS name token."""
    name = vehicle.replace("-", "_")
    return name if name[:1].isalpha() else f"v{name}"


@dataclass(frozen=True)
class RosMessage:
    topic: str  # /layerpilot/uav1/pose
    type: ros.RosType
    message: object  # a rosbags message instance
    stamp: float  # mission clock seconds


@dataclass
class _Path:
    poses: list[tuple[float, Pose]] = field(default_factory=list)
    sent_at: float = -np.inf


class Ros2Topics:
    """Translates bus messages (key, payload) into ROS 2 messages; keeps each vehicle's flown path.

    A payload that does not decode raises BadMessage (layerpilot.bus.reject), as on the bus."""

    BUS_TOPICS = ("pose", "decision", "cloud", "layers")

    def __init__(self, cfg: Ros2Config) -> None:
        self.cfg = cfg
        self._paths: dict[str, _Path] = {}

    OUTPUTS = (("pose", ros.POSE_STAMPED), ("path", ros.PATH), ("target", ros.POSE_STAMPED),
               ("cloud", ros.POINT_CLOUD2), ("map", ros.OCCUPANCY_GRID), ("grid_map", ros.GRID_MAP),
               ("octomap", ros.OCTOMAP))

    def topic(self, vehicle: str, name: str) -> str:
        return f"{self.cfg.namespace}/{ros_vehicle(vehicle)}/{name}"

    def outputs(self, vehicle: str) -> list[tuple[str, ros.RosType]]:
        """Every ROS 2 topic a vehicle's messages become, with its type."""
        return [(self.topic(vehicle, name), ros.RosType(type_name)) for name, type_name in self.OUTPUTS]

    def translate(self, bus_topic: str, payload: bytes) -> list[RosMessage]:
        if bus_topic == "pose":
            s = bus.decode_state(payload)
            out = [RosMessage(self.topic(s.vehicle, "pose"), ros.RosType(ros.POSE_STAMPED),
                              ros.pose_stamped(s.stamp, s.pose), s.stamp)]
            return out + self._path(s)
        if bus_topic == "decision":
            d = bus.decode_decision(payload)
            return [RosMessage(self.topic(d.vehicle, "target"), ros.RosType(ros.POSE_STAMPED),
                               ros.pose_stamped(d.stamp, position=d.waypoint), d.stamp)]
        if bus_topic == "cloud":
            c = bus.decode_cloud(payload)
            return [RosMessage(self.topic(c.vehicle, "cloud"), ros.RosType(ros.POINT_CLOUD2),
                               ros.point_cloud2(c.cloud), c.cloud.stamp)]
        if bus_topic == "layers":
            ls = decode_layer_set(payload)
            cl = to_column_layers(ls)
            return [RosMessage(self.topic(ls.vehicle, "map"), ros.RosType(ros.OCCUPANCY_GRID),
                               ros.occupancy_grid(ls.stamp, cl), ls.stamp),
                    RosMessage(self.topic(ls.vehicle, "grid_map"), ros.RosType(ros.GRID_MAP),
                               ros.grid_map(ls.stamp, cl), ls.stamp)]
        return []

    def octomap(self, vehicle: str, stamp: float, bt: bytes) -> RosMessage:
        """The map server's ``map/octree`` reply (a ``.bt`` stream) as the vehicle's octomap topic."""
        try:
            message = ros.octomap(stamp, bt)
        except ValueError as exc:
            raise BadMessage("bad octree", str(exc)) from None
        return RosMessage(self.topic(vehicle, "octomap"), ros.RosType(ros.OCTOMAP), message, stamp)

    def _path(self, s: bus.State) -> list[RosMessage]:
        p = self._paths.setdefault(s.vehicle, _Path())
        if not p.poses or np.linalg.norm(p.poses[-1][1].position - s.pose.position) >= self.cfg.path_spacing:
            p.poses.append((s.stamp, s.pose))
            del p.poses[:-self.cfg.path_poses]
        if s.stamp - p.sent_at < 1.0 / self.cfg.path_rate and s.stamp >= p.sent_at:
            return []
        p.sent_at = s.stamp
        return [RosMessage(self.topic(s.vehicle, "path"), ros.RosType(ros.PATH), ros.path(s.stamp, p.poses),
                           s.stamp)]
