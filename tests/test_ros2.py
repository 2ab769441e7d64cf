"""ROS 2 without ROS: rmw_zenoh's key expressions, tokens and attachment, CDR that a ROS 2 decoder reads, the
bridge on a secured bus, and recordings with ROS 2 channels that mcap's ROS 2 decoder reads back."""

from __future__ import annotations

import time

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import zenoh
from zenoh.ext import Int64, UInt8, z_deserialize

from layerpilot.bus import messages as bus
from layerpilot.bus.keys import Keys
from layerpilot.bus.layerset import GridLayersMessage, encode_layer_set
from layerpilot.bus.recording import RecordingReader, RecordingWriter
from layerpilot.bus.reject import BadMessage
from layerpilot.bus.security import open_hub, open_node_session
from layerpilot.bus.session import BusConfig, free_endpoint, publish
from layerpilot.config import ConfigError
from layerpilot.geometry import PointCloud, Pose
from layerpilot.grid import GridGeometry
from layerpilot.map import VoxelMap
from layerpilot.nodes.ros2 import Ros2Bridge
from layerpilot.ros2 import messages as ros
from layerpilot.ros2.recording import recording_options
from layerpilot.ros2.rmw_zenoh import attachment, topic_key
from layerpilot.ros2.topics import Ros2Config, Ros2Topics

K = Keys("uav1")
GEOMETRY = GridGeometry(-20.0, -10.0, 1.0, 6, 4)  # 6 columns along x, 4 rows along y


def layer_set() -> GridLayersMessage:
    h, w = GEOMETRY.shape
    observed = np.zeros((h, w), bool)
    observed[3, 5] = True  # the north-east cell
    observed[0, 0] = True  # the south-west cell
    elevation = np.where(observed, 0.0, np.nan).astype(np.float32)
    elevation[3, 5], elevation[0, 0] = 7.5, -1.25
    color = np.zeros((h, w, 3), np.uint8)
    color[3, 5] = (10, 20, 30)
    return GridLayersMessage(42.5, "uav1", GEOMETRY, {
        "observed": observed, "elevation": elevation, "color": color,
        "last_seen": np.where(observed, 40.0, np.nan), "min_distance": np.where(observed, 12.0, np.inf)})


def state(stamp: float, x: float) -> bytes:
    q = np.array([np.cos(0.25), 0.0, 0.0, np.sin(0.25)])  # yaw 0.5 rad
    return bus.encode_state(bus.State(stamp, "uav1", Pose(np.array([x, 2.0, 30.0]), q), armed=True, mode="GUIDED"))


def cloud() -> bytes:
    points = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [-1.0, 0.5, 2.0]], np.float32)
    colors = np.array([[255, 0, 0], [0, 255, 0], [1, 2, 3]], np.uint8)
    return bus.encode_cloud(bus.CloudMessage("uav1", 7, PointCloud(points, np.array([0.0, 0.0, 30.0]), 41.0, colors)))


def unpack(raw: bytes) -> tuple[int, int, bytes]:
    """An attachment read back with zenoh-ext's own deserializer, as rmw_zenoh's C++ does."""
    seq, stamp, gid = z_deserialize(tuple[Int64, Int64, tuple[(UInt8,) * 16]], zenoh.ZBytes(raw))
    return seq, stamp, bytes(gid)


def test_type_names_and_hashes_are_rmw_zenohs():
    """std_msgs/msg/String's hash is the one ROS 2 Jazzy publishes (rmw_zenoh's design document quotes its
    key expression ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c74...``)."""
    string = ros.RosType("std_msgs/msg/String")
    assert topic_key(0, "/chatter", string) == (
        "0/chatter/std_msgs::msg::dds_::String_/"
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18")
    pose = ros.RosType(ros.POSE_STAMPED)
    assert pose.dds_name == "geometry_msgs::msg::dds_::PoseStamped_"
    assert topic_key(3, "/layerpilot/uav1/pose", pose).startswith("3/layerpilot/uav1/pose/geometry_msgs::msg::")
    assert pose.definition.startswith("std_msgs/Header header\ngeometry_msgs/Pose pose\n")
    assert "MSG: builtin_interfaces/Time" in pose.definition


def test_the_attachment_is_two_int64_and_a_16_byte_gid():
    gid = bytes(range(16))
    raw = attachment(5, 1_700_000_000_123_456_789, gid)
    assert len(raw) == 32
    assert unpack(raw) == (5, 1_700_000_000_123_456_789, gid)
    with pytest.raises(ValueError, match="gid: expected 16 bytes, got 3"):
        attachment(1, 0, b"abc")


def test_every_translated_message_decodes_into_the_expected_fields():
    topics = Ros2Topics(Ros2Config())
    [pose, path] = topics.translate("pose", state(40.25, 3.0))
    assert (pose.topic, path.topic) == ("/layerpilot/uav1/pose", "/layerpilot/uav1/path")
    p = ros.deserialize(ros.serialize(pose.message, pose.type.name), ros.POSE_STAMPED)
    assert (p.header.stamp.sec, p.header.stamp.nanosec, p.header.frame_id) == (40, 250_000_000, "map")
    assert (p.pose.position.x, p.pose.position.y, p.pose.position.z) == (3.0, 2.0, 30.0)
    assert p.pose.orientation.z == pytest.approx(np.sin(0.25)) and p.pose.orientation.w == pytest.approx(np.cos(0.25))

    [pc] = topics.translate("cloud", cloud())
    c = ros.deserialize(ros.serialize(pc.message, pc.type.name), ros.POINT_CLOUD2)
    assert [(f.name, f.offset, f.datatype) for f in c.fields] == [("x", 0, 7), ("y", 4, 7), ("z", 8, 7),
                                                                  ("rgb", 12, 7)]
    assert (c.width, c.height, c.point_step, c.row_step) == (3, 1, 16, 48)
    rows = np.frombuffer(bytes(c.data), np.float32).reshape(3, 4)
    assert rows[1, :3].tolist() == [4.0, 5.0, 6.0]
    rgb = rows[:, 3].view(np.uint32)
    assert [(v >> 16 & 255, v >> 8 & 255, v & 255) for v in rgb.tolist()] == [(255, 0, 0), (0, 255, 0), (1, 2, 3)]

    grid, gm = topics.translate("layers", encode_layer_set(layer_set()))
    assert (grid.topic, gm.topic) == ("/layerpilot/uav1/map", "/layerpilot/uav1/grid_map")
    g = ros.deserialize(ros.serialize(grid.message, grid.type.name), ros.OCCUPANCY_GRID)
    assert (g.info.width, g.info.height, g.info.resolution) == (6, 4, 1.0)
    assert (g.info.origin.position.x, g.info.origin.position.y) == (-20.0, -10.0)
    cells = np.asarray(g.data).reshape(4, 6)  # row-major from the south-west cell
    assert cells[0, 0] == 0 and cells[3, 5] == 0 and (cells == -1).sum() == 22

    m = ros.deserialize(ros.serialize(gm.message, gm.type.name), ros.GRID_MAP)
    assert list(m.layers) == ["elevation", "observed", "last_seen", "min_distance", "color"]
    assert (m.info.length_x, m.info.length_y) == (6.0, 4.0)
    assert (m.info.pose.position.x, m.info.pose.position.y) == (-17.0, -8.0)  # the grid's centre
    elevation = np.asarray(m.data[0].data)
    assert [d.label for d in m.data[0].layout.dim] == ["column_index", "row_index"]
    assert elevation[0] == 7.5  # grid_map's index (0, 0) is the +x +y corner: the north-east cell
    assert elevation[-1] == -1.25  # and the last is the south-west one
    assert np.isnan(elevation).sum() == 22
    assert np.asarray(m.data[4].data)[:1].view(np.uint32)[0] == (10 << 16 | 20 << 8 | 30)


def test_an_octree_becomes_the_octomap_message_octomap_msgs_makes_of_it():
    vm = VoxelMap(0.5)
    points = np.random.default_rng(0).uniform(-10, 10, (2000, 3)).astype(np.float32)
    vm.insert(points, np.array([0.0, 0.0, 30.0]), None, stamp=1.0)
    m = Ros2Topics(Ros2Config()).octomap("uav1", 12.0, vm.to_bytes(".bt"))
    assert m.topic == "/layerpilot/uav1/octomap"
    back = ros.deserialize(ros.serialize(m.message, m.type.name), ros.OCTOMAP)
    assert (back.binary, back.id, back.resolution, back.header.stamp.sec) == (True, "OcTree", 0.5, 12)
    # octomap_msgs' binaryMapToMsg carries writeBinaryData: the .bt file's tree stream, without its header
    assert np.asarray(back.data, np.int8).tobytes() == vm.to_bytes(".bt").partition(b"\ndata\n")[2]
    with pytest.raises(BadMessage, match="bad octree: not an OctoMap .bt stream"):
        Ros2Topics(Ros2Config()).octomap("uav1", 12.0, b"hello")


def test_the_path_keeps_poses_a_spacing_apart_and_goes_out_at_its_rate():
    topics = Ros2Topics(Ros2Config(path_rate=1.0, path_spacing=1.0))
    sent = []
    for i in range(21):  # 20 Hz for 1 s, 0.1 m a step
        sent += [m for m in topics.translate("pose", state(10.0 + i * 0.05, i * 0.1)) if m.topic.endswith("path")]
    assert len(sent) == 2  # at 10.0 s and 11.0 s
    assert [p.pose.position.x for p in sent[-1].message.poses] == pytest.approx([0.0, 1.0, 2.0])


def test_bad_ros2_settings_name_the_key():
    with pytest.raises(ConfigError, match=r"ros2.namespace: expected an absolute ROS name"):
        Ros2Config(namespace="layer pilot")
    with pytest.raises(ConfigError, match=r"ros2.domain_id"):
        Ros2Config(domain_id=300)


def wait_for(condition, timeout: float = 5.0) -> None:
    end = time.monotonic() + timeout
    while not condition() and time.monotonic() < end:
        time.sleep(0.05)


def test_the_bridge_on_a_secured_bus_publishes_rmw_zenoh_topics_that_a_ros2_tool_sees(tmp_path):
    """The bridge logs in as ros2-uav1; a ROS 2 tool logging in as the operator lists the node and its
    publishers from their liveliness tokens (as ``ros2 topic list`` does) and receives CDR samples with
    rmw_zenoh's attachment; the operator cannot publish on the ROS 2 keys."""
    cfg = BusConfig(endpoint=free_endpoint())
    hub, secrets = open_hub(cfg, tmp_path / "secrets", ["uav1"], ros2=(0, "/layerpilot"))
    sessions = {user: open_node_session(cfg, secrets.credentials_file(user))
                for user in ("ros2-uav1", "link-uav1", "depth-uav1", "map-server", "operator")}
    bridge = Ros2Bridge(sessions["ros2-uav1"], "uav1", Ros2Config(octomap_period=0))  # no map server here
    received: dict[str, list] = {}
    tool = sessions["operator"]
    sub = tool.declare_subscriber("0/layerpilot/uav1/**", lambda s: received.setdefault(
        str(s.key_expr).split("/")[3], []).append((s.payload.to_bytes(), s.attachment.to_bytes())))
    bridge.start()
    try:
        time.sleep(0.5)
        for i in range(3):
            publish(sessions["link-uav1"], K.pose, state(40.0 + i, float(i)))
        publish(sessions["depth-uav1"], K.cloud, cloud())
        publish(sessions["map-server"], K.layers, encode_layer_set(layer_set()))
        publish(sessions["link-uav1"], K.pose, b"not a state")
        wait_for(lambda: {"pose", "path", "cloud", "map", "grid_map"} <= set(received) and len(received["pose"]) == 3)
        assert {"pose", "path", "cloud", "map", "grid_map"} <= set(received)
        payloads = [ros.deserialize(p, ros.POSE_STAMPED) for p, _ in received["pose"]]
        assert [m.pose.position.x for m in payloads] == [0.0, 1.0, 2.0]
        sequence = [unpack(a)[0] for _, a in received["pose"]]
        assert sequence == [1, 2, 3]
        assert ros.deserialize(received["cloud"][0][0], ros.POINT_CLOUD2).width == 3
        assert ros.deserialize(received["map"][0][0], ros.OCCUPANCY_GRID).info.width == 6
        tokens = sorted(str(r.ok.key_expr) for r in tool.liveliness().get("@ros2_lv/0/**", timeout=2.0))
        zid = str(sessions["ros2-uav1"].zid())
        assert f"@ros2_lv/0/{zid}/0/0/NN/%/%layerpilot/uav1_bridge" in tokens
        pose_hash = ros.RosType(ros.POSE_STAMPED).hash
        assert any(t.startswith(f"@ros2_lv/0/{zid}/0/") and t.endswith(
            f"/MP/%/%layerpilot/uav1_bridge/%layerpilot%uav1%pose/geometry_msgs::msg::dds_::PoseStamped_/"
            f"{pose_hash}/:2:,10:,:,:,,") for t in tokens), tokens
        assert len(tokens) == 1 + 7  # the node and its seven publishers, announced at its start
        assert bridge.rejects.total == 1 and bridge.status()["published"]["/layerpilot/uav1/pose"] == 3
        forged = []
        sessions["link-uav1"].declare_subscriber("0/**", lambda s: forged.append(s))
        tool.put(topic_key(0, "/layerpilot/uav1/pose", ros.RosType(ros.POSE_STAMPED)), b"forged")
        time.sleep(0.3)
        assert len(received["pose"]) == 3  # the operator's put reached no one
    finally:
        bridge.stop()
        sub.undeclare()
        for s in (*sessions.values(), hub):
            s.close()


@pytest.mark.parametrize("mode", ["beside", "only"])
def test_a_recording_with_ros2_channels_reads_back_with_mcaps_ros2_decoder(tmp_path, mode):
    path = tmp_path / "mission.mcap"
    with RecordingWriter(path, "[ros2]\n", **recording_options(mode, Ros2Config())) as w:
        w.write(K.pose, state(40.0, 1.0), log_time=1)
        w.write(K.cloud, cloud(), log_time=2)
        w.write(K.layers, encode_layer_set(layer_set()), log_time=3)
    decoded = {}
    with open(path, "rb") as f:
        for schema, channel, message, ros_msg in make_reader(f, decoder_factories=[DecoderFactory()]) \
                .iter_decoded_messages(topics=["/layerpilot/uav1/pose", "/layerpilot/uav1/cloud",
                                               "/layerpilot/uav1/map", "/layerpilot/uav1/grid_map",
                                               "/layerpilot/uav1/path"]):
            assert (schema.encoding, channel.message_encoding) == ("ros2msg", "cdr")
            decoded[channel.topic] = (schema.name, ros_msg)
    assert decoded["/layerpilot/uav1/pose"][0] == "geometry_msgs/msg/PoseStamped"
    assert decoded["/layerpilot/uav1/pose"][1].pose.position.x == 1.0
    assert decoded["/layerpilot/uav1/cloud"][1].width == 3
    assert decoded["/layerpilot/uav1/map"][1].info.height == 4
    assert decoded["/layerpilot/uav1/grid_map"][0] == "grid_map_msgs/msg/GridMap"
    assert list(decoded["/layerpilot/uav1/grid_map"][1].layers)[0] == "elevation"
    reader = RecordingReader(path)
    ours = [m.topic for m in reader.messages()]
    assert ours == (["pose", "cloud", "layers"] if mode == "beside" else [])
    assert reader.ros2_messages == 5 and not reader.unknown_schemas
    with pytest.raises(ValueError, match="--ros2: expected one of off, beside, only"):
        recording_options("both", Ros2Config())


def test_up_with_ros2_enabled_runs_the_bridge_and_records_ros2_channels(tmp_path):
    """A live mission with ``[ros2] enabled``: `up` starts ros2/uav1 with its own login; a ROS 2 tool (the
    operator's login) receives the pose, the target, the map and the map server's octree as CDR; ``--record --ros2 beside`` holds
    both the protobuf and the ROS 2 channels."""
    from conftest import free_tcp_port, operator_session, start_up, stop_up

    ep = free_endpoint()
    mission = tmp_path / "mission.toml"
    mission.write_text(f"""
speed = 4.0
mavlink_port = {free_tcp_port()}
[map_server]
snapshot = ""
[depth]
source = "ground_truth"
stride = 4
[sim]
frame_rate_hz = 2.0
[sim.camera]
width = 160
height = 120
[ros2]
enabled = true
domain_id = 7
octomap_period = 1.0
""")
    recording = tmp_path / "mission.mcap"
    up, lines = start_up(mission, ep, tmp_path / "logs", "--record", str(recording), "--ros2", "beside")
    client = None
    got: dict[str, list[bytes]] = {}
    try:
        client = operator_session(ep, tmp_path / "logs")
        sub = client.declare_subscriber("7/layerpilot/uav1/**", lambda s: got.setdefault(
            str(s.key_expr).split("/")[3], []).append(s.payload.to_bytes()))
        end = time.monotonic() + 120
        def climbing() -> bool:  # the bridge's pose follows the vehicle up
            return any(ros.deserialize(p, ros.POSE_STAMPED).pose.position.z > 5.0 for p in got.get("pose", [])[-5:])
        def mapped() -> bool:  # an octomap of the map the clouds built, not the first, empty one
            return any(len(ros.deserialize(p, ros.OCTOMAP).data) > 1000 for p in got.get("octomap", [])[-2:])
        while not ({"pose", "target", "map", "cloud"} <= set(got) and climbing() and mapped()):
            assert up.poll() is None, "up exited:\n" + "".join(lines[-30:])
            assert time.monotonic() < end, f"only {sorted(got)}:\n" + "".join(lines[-30:])
            time.sleep(0.2)
        sub.undeclare()
        target = ros.deserialize(got["target"][-1], ros.POSE_STAMPED)
        assert target.header.frame_id == "map" and np.isfinite(target.pose.position.x)
        assert ros.deserialize(got["map"][-1], ros.OCCUPANCY_GRID).info.width == 256  # the mission's window
        octomap = ros.deserialize(got["octomap"][-1], ros.OCTOMAP)
        assert (octomap.id, octomap.resolution, octomap.binary) == ("OcTree", 1.0, True) and len(octomap.data) > 1000
    finally:
        if client is not None:
            client.close()
        stop_up(up)
    assert up.returncode == 0, "".join(lines[-20:])
    assert any(line.startswith("ros2/uav1") and " alive " in line for line in lines), "".join(lines[-20:])
    with open(recording, "rb") as f:
        channels = {c.topic: c.message_encoding for c in make_reader(f).get_summary().channels.values()}
    assert channels["/layerpilot/uav1/pose"] == "cdr" and channels["layerpilot/uav1/pose"] == "protobuf"
    assert {"/layerpilot/uav1/map", "/layerpilot/uav1/grid_map", "/layerpilot/uav1/cloud"} <= set(channels)
