"""layerpilot's messages as ROS 2 messages: the types, their definitions and hashes, and CDR.

The type store is rosbags' (a maintained, pure-Python ROS 2 type system and CDR serializer) for
ROS 2 Jazzy, plus grid_map_msgs and octomap_msgs (not in rosbags' stores) from their ROS 2 definitions. rosbags also
computes each type's REP-2016 hash (``RIHS01_...``), the hash rmw_zenoh puts in its key
expressions and ``ros2 bag`` in its metadata.

Everything is in the ``map`` frame (ENU metres, z up), stamped on the mission clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from layerpilot.geometry import PointCloud, Pose
from layerpilot.map.columns import ColumnLayers

FRAME = "map"

# grid_map_msgs on ROS 2 Jazzy (ANYbotics/grid_map, branch jazzy): what RViz's grid_map plugin reads;
# octomap_msgs (OctoMap/octomap_msgs, branch ros2): what octomap_rviz_plugins and octomap_server read
_EXTRA_MSGS = {
    "octomap_msgs/msg/Octomap": "std_msgs/Header header\nbool binary\nstring id\nfloat64 resolution\n"
                                "int8[] data\n",
    "grid_map_msgs/msg/GridMapInfo": "float64 resolution\nfloat64 length_x\nfloat64 length_y\n"
                                     "geometry_msgs/Pose pose\n",
    "grid_map_msgs/msg/GridMap": "std_msgs/Header header\ngrid_map_msgs/GridMapInfo info\nstring[] layers\n"
                                 "string[] basic_layers\nstd_msgs/Float32MultiArray[] data\n"
                                 "uint16 outer_start_index\nuint16 inner_start_index\n",
}
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
PATH = "nav_msgs/msg/Path"
POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
GRID_MAP = "grid_map_msgs/msg/GridMap"
OCTOMAP = "octomap_msgs/msg/Octomap"
GRID_MAP_LAYERS = ("elevation", "observed", "last_seen", "min_distance", "color")


@lru_cache(maxsize=1)
def typestore():
    """rosbags' ROS 2 Jazzy types with grid_map_msgs and octomap_msgs added."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for name, text in _EXTRA_MSGS.items():
        store.register(get_types_from_msg(text, name))
    return store


@dataclass(frozen=True)
class RosType:
    """One ROS 2 message type as the middleware and recordings name it."""

    name: str  # geometry_msgs/msg/PoseStamped

    @property
    def dds_name(self) -> str:
        """The name rmw implementations put on the wire: ``geometry_msgs::msg::dds_::PoseStamped_``."""
        package, kind, message = self.name.split("/")
        return f"{package}::{kind}::dds_::{message}_"

    @property
    def hash(self) -> str:
        """REP-2016's type hash, ``RIHS01_<sha256 hex>``."""
        return typestore().hash_rihs01(self.name)

    @property
    def definition(self) -> str:
        """The concatenated ``.msg`` text (MCAP's ``ros2msg`` schema encoding, ``ros2 bag``'s too)."""
        return typestore().generate_msgdef(self.name, ros_version=2)[0]


def serialize(message: object, type_name: str) -> bytes:
    """Little-endian CDR with its encapsulation header, as ROS 2 publishes it."""
    return bytes(typestore().serialize_cdr(message, type_name, little_endian=True))


def deserialize(data: bytes, type_name: str) -> object:
    return typestore().deserialize_cdr(data, type_name)


def _types():
    return typestore().types


def _header(stamp: float):
    t = _types()
    sec = math.floor(stamp)
    nanosec = min(int(round((stamp - sec) * 1e9)), 999_999_999)
    return t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=nanosec),
                                    frame_id=FRAME)


def _pose(position: np.ndarray, orientation_wxyz: np.ndarray | None = None):
    t = _types()
    w, x, y, z = (1.0, 0.0, 0.0, 0.0) if orientation_wxyz is None else (float(v) for v in orientation_wxyz)
    p = np.asarray(position, np.float64)
    return t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]),
                                                                           z=float(p[2])),
                                       orientation=t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w))


def pose_stamped(stamp: float, pose: Pose | None = None, position: np.ndarray | None = None):
    """A vehicle's pose (``pose``), or a bare position such as a target (identity orientation)."""
    if pose is not None:
        return _types()[POSE_STAMPED](header=_header(stamp), pose=_pose(pose.position, pose.orientation))
    return _types()[POSE_STAMPED](header=_header(stamp), pose=_pose(position))


def path(stamp: float, poses: list[tuple[float, Pose]]):
    """The flown path: one PoseStamped per kept pose."""
    return _types()[PATH](header=_header(stamp), poses=[pose_stamped(s, p) for s, p in poses])


def point_cloud2(cloud: PointCloud):
    """x, y, z as float32 and, with colors, ``rgb`` packed as PCL does (0x00RRGGBB in a float32's bits)."""
    t = _types()
    field = t["sensor_msgs/msg/PointField"]
    n = len(cloud.points)
    fields = [field(name=a, offset=4 * i, datatype=field.FLOAT32, count=1) for i, a in enumerate("xyz")]
    if cloud.colors is not None:
        fields.append(field(name="rgb", offset=12, datatype=field.FLOAT32, count=1))
        packed = np.zeros((n, 4), np.float32)
        packed[:, :3] = cloud.points
        rgb = cloud.colors.astype(np.uint32)
        packed[:, 3] = ((rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]).view(np.float32)
    else:
        packed = np.ascontiguousarray(cloud.points, np.float32)
    step = 4 * len(fields)
    return t[POINT_CLOUD2](header=_header(cloud.stamp), height=1, width=n, fields=fields, is_bigendian=False,
                           point_step=step, row_step=step * n, data=packed.reshape(-1).view(np.uint8),
                           is_dense=True)


def occupancy_grid(stamp: float, layers: ColumnLayers):
    """Where the map has seen the ground: -1 unknown, 0 observed (the exploration view RViz and Nav2 show).

    Row-major from the grid's south-west cell, rows along y: the layer arrays' own order."""
    t = _types()
    g = layers.geometry
    info = t["nav_msgs/msg/MapMetaData"](map_load_time=_header(stamp).stamp, resolution=float(g.resolution),
                                         width=g.width, height=g.height,
                                         origin=_pose(np.array([g.origin_x, g.origin_y, 0.0])))
    data = np.where(layers.observed, 0, -1).astype(np.int8).reshape(-1)
    return t[OCCUPANCY_GRID](header=_header(stamp), info=info, data=data)


def _grid_map_order(values: np.ndarray) -> np.ndarray:
    """grid_map's storage: index (0, 0) at the map's +x +y corner, rows along -x, columns along -y, column-major;
    of a (rows = y, columns = x) array that is both axes reversed, row-major."""
    return np.ascontiguousarray(values[::-1, ::-1], np.float32).reshape(-1)


def grid_map(stamp: float, layers: ColumnLayers):
    """Every column layer as one grid_map layer, float32, NaN where unobserved; ``color`` packed RGB as
    grid_map_ros' colour layers are."""
    t = _types()
    g = layers.geometry
    observed = layers.observed
    rgb = layers.color.astype(np.uint32)
    packed = ((rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]).view(np.float32)
    values = {"elevation": layers.elevation, "observed": np.where(observed, 1.0, np.nan),
              "last_seen": layers.last_seen, "min_distance": layers.min_distance, "color": packed}
    dim = t["std_msgs/msg/MultiArrayDimension"]
    layout = t["std_msgs/msg/MultiArrayLayout"](dim=[dim(label="column_index", size=g.height,
                                                          stride=g.height * g.width),
                                                      dim(label="row_index", size=g.width, stride=g.width)],
                                                 data_offset=0)
    data = [t["std_msgs/msg/Float32MultiArray"](layout=layout,
                                               data=_grid_map_order(np.where(observed, values[n], np.nan)))
            for n in GRID_MAP_LAYERS]
    x0, x1, y0, y1 = g.extent
    info = t["grid_map_msgs/msg/GridMapInfo"](resolution=float(g.resolution), length_x=float(x1 - x0),
                                              length_y=float(y1 - y0),
                                              pose=_pose(np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])))
    return t[GRID_MAP](header=_header(stamp), info=info, layers=list(GRID_MAP_LAYERS), basic_layers=["elevation"],
                       data=data, outer_start_index=0, inner_start_index=0)


def octomap(stamp: float, bt: bytes):
    """An OctoMap ``.bt`` stream as octomap_msgs carries it (``binaryMapToMsg``): id and resolution from the
    stream's header, the tree's data after it; ValueError if ``bt`` is not one."""
    head, sep, data = bt.partition(b"\ndata\n")
    fields = dict(line.split(" ", 1) for line in head.decode("ascii", "replace").splitlines()[1:]
                  if line and not line.startswith("#") and " " in line)
    if not sep or not bt.startswith(b"# Octomap OcTree binary file") or "res" not in fields:
        raise ValueError("not an OctoMap .bt stream (no '# Octomap OcTree binary file' header with res and data)")
    return _types()[OCTOMAP](header=_header(stamp), binary=True, id=fields.get("id", "OcTree"),
                             resolution=float(fields["res"]), data=np.frombuffer(data, np.int8))
