"""Codec round trips of every bus message, compact layer encodings, and the 1 MB limit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys, all_vehicles, vehicle_of
from layerpilot.bus.layerset import (GridLayersMessage, column_arrays, decode_layer_set, encode_layer_set,
                                     to_column_layers)
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage
from layerpilot.geometry import CameraFrame, CameraIntrinsics, PointCloud, Pose
from layerpilot.grid import GridGeometry
from layerpilot.map.columns import ColumnLayers

rng = np.random.default_rng(7)


def test_generated_code_imports_with_installed_runtime():
    import google.protobuf

    assert pb.PointCloud.DESCRIPTOR.full_name == "layerpilot.PointCloud"
    assert int(google.protobuf.__version__.split(".")[0]) >= 4


def test_keys():
    k = Keys("uav1")
    assert k.cloud == "layerpilot/uav1/cloud"
    assert k.service("voxels") == "layerpilot/uav1/map/voxels"
    assert all_vehicles("cloud") == "layerpilot/*/cloud"
    assert vehicle_of("layerpilot/uav2/map/stats") == "uav2"
    with pytest.raises(ValueError, match="vehicle"):
        Keys("a/b")
    with pytest.raises(ValueError, match="topic"):
        k.topic("nope")
    assert k.health("map-server") == "layerpilot/uav1/health/map-server"
    assert k.aggregates == "layerpilot/uav1/decide/aggregates"
    with pytest.raises(ValueError, match="unknown node 'view'"):
        k.health("view")


def test_health_round_trip_and_rejections():
    status = {"received": 12, "dropped": 1, "loops": {"map-insert": 0.2}, "telemetry": "GUIDED armed"}
    h = msg.decode_health(msg.encode_health(msg.NodeHealth("uav1", "map-server", 12.5, status)))
    assert h == msg.NodeHealth("uav1", "map-server", 12.5, status)
    with pytest.raises(ValueError, match="Out of range float values"):  # NaN is not JSON: refused at the sender
        msg.encode_health(msg.NodeHealth("uav1", "decide", 1.0, {"x": math.nan}))
    for m, reason in ((pb.NodeHealth(vehicle="uav1", node="decide", status="{oops"), "not JSON"),
                      (pb.NodeHealth(vehicle="uav1", node="decide", status="[1, 2]"), "a JSON object expected"),
                      (pb.NodeHealth(vehicle="uav1", node="router", status="{}"), "'router' is not one of"),
                      (pb.NodeHealth(vehicle="uav1", node="decide", uptime=math.inf, status="{}"), "uptime")):
        with pytest.raises(BadMessage, match=reason):
            msg.decode_health(m.SerializeToString())


def test_cloud_round_trip():
    pts = rng.normal(size=(1000, 3)).astype(np.float32)
    cols = rng.integers(0, 256, (1000, 3), dtype=np.uint8)
    m = msg.decode_cloud(msg.encode_cloud(msg.CloudMessage("uav1", 3, PointCloud(pts, [1.0, 2, 3], 12.5, cols), 40.0)))
    c = m.cloud
    assert (c.stamp, m.vehicle, m.seq, m.max_range) == (12.5, "uav1", 3, 40.0)
    np.testing.assert_array_equal(c.points, pts)
    np.testing.assert_array_equal(c.colors, cols)
    np.testing.assert_array_equal(c.origin, [1, 2, 3])
    empty = msg.CloudMessage("u", 0, PointCloud(pts[:0], np.zeros(3), 0.0))
    back = msg.decode_cloud(msg.encode_cloud(empty)).cloud
    assert back.points.shape == (0, 3) and back.colors is None
    with pytest.raises(ValueError, match="cloud"):
        msg.encode_cloud(msg.CloudMessage("u", 0, pts))


def test_frame_state_waypoint_decision_mission_round_trip():
    img = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    depth = rng.random((48, 64)).astype(np.float32)
    depth[0, 0] = np.nan  # no measurement is allowed
    pose = Pose(np.array([1.0, 2, 3]), np.array([0.5, 0.5, 0.5, 0.5]))
    k = CameraIntrinsics(50, 51, 32, 24, 64, 48)
    m = msg.decode_frame(msg.encode_frame(msg.FrameMessage("uav1", 9, CameraFrame(img, pose, k, 1.0, depth))))
    f = m.frame
    np.testing.assert_array_equal(f.image, img)
    np.testing.assert_array_equal(f.depth, depth)
    assert f.intrinsics == k and f.stamp == 1.0 and (m.vehicle, m.seq) == ("uav1", 9)
    assert f.pose == pose
    no_depth = msg.decode_frame(msg.encode_frame(msg.FrameMessage("uav1", 10, CameraFrame(img, pose, k, 1.0))))
    assert no_depth.frame.depth is None

    body = Pose.from_euler(0.1, -0.05, 2.0, (1.0, 2, 30))
    s = msg.decode_state(msg.encode_state(msg.State(2.0, "uav1", body, np.array([0.5, 0, 0]), True, "GUIDED", 0.8)))
    assert s.armed and s.mode == "GUIDED" and s.battery == 0.8
    assert s.pose == body
    np.testing.assert_array_equal(s.position, [1, 2, 30])

    w = msg.decode_waypoint(msg.encode_waypoint(msg.Waypoint(3.0, "uav1", 4, np.array([5.0, 6, 20]))))
    assert w.seq == 4 and math.isnan(w.yaw)
    np.testing.assert_array_equal(w.position, [5, 6, 20])

    terms = (msg.Term("fringe", 0.5, 0.8, 0.4), msg.Term("distance", 0.5, 0.2, 0.1))
    d = msg.decode_decision(msg.encode_decision(msg.Decision(4.0, "uav1", 5, np.array([5.0, 6, 20]), 0.5, terms, "balanced")))
    assert d.terms == terms and d.score == 0.5 and d.behavior == "balanced"

    m = msg.decode_mission_state(msg.encode_mission_state(msg.MissionState(5.0, "uav1", "survey", 3, 2, 120.5)))
    assert (m.phase, m.waypoints_sent, m.waypoints_reached, m.distance_flown) == ("survey", 3, 2, 120.5)


def _columns(g: GridGeometry, smooth: bool = True) -> ColumnLayers:
    h, w = g.shape
    yy, xx = np.mgrid[0:h, 0:w]
    observed = (xx - w / 2) ** 2 + (yy - h / 2) ** 2 < (0.45 * w) ** 2
    elevation = np.where(observed, 10 + 5 * np.sin(xx / 17.0) * np.cos(yy / 23.0), np.nan).astype(np.float32)
    color = np.zeros((h, w, 3), np.uint8)
    color[observed] = (30, 120, 40)
    last_seen = np.where(observed, 100.0 + xx * 0.5, np.nan)
    min_distance = np.where(observed, 5.0 + yy * 0.1, np.inf).astype(np.float32)
    return ColumnLayers(g, observed, elevation, color, last_seen, min_distance)


def test_layer_set_512_round_trip_under_1mb_with_bounded_error():
    g = GridGeometry(-128.0, -128.0, 0.5, 512, 512)
    cl = _columns(g)
    data = encode_layer_set(GridLayersMessage(100.0, "uav1", g, column_arrays(cl)))
    assert len(data) < 1_000_000
    back = to_column_layers(decode_layer_set(data))
    assert back.geometry == g
    np.testing.assert_array_equal(back.observed, cl.observed)
    np.testing.assert_array_equal(back.color, cl.color)
    np.testing.assert_array_equal(np.isnan(back.elevation), np.isnan(cl.elevation))
    np.testing.assert_array_equal(np.isinf(back.min_distance), np.isinf(cl.min_distance))
    obs = cl.observed
    assert np.abs(back.elevation[obs] - cl.elevation[obs]).max() < 0.01  # float16 at 5..15 m
    span = np.nanmax(cl.last_seen) - np.nanmin(cl.last_seen)
    assert np.abs(back.last_seen[obs] - cl.last_seen[obs]).max() <= span / 65532 + 1e-9  # uint16 quantization


def test_layer_set_falls_back_to_uint8_then_refuses():
    g = GridGeometry(0.0, 0.0, 1.0, 512, 512)
    noise = {"a": rng.random((512, 512)).astype(np.float32) * 100, "b": rng.random((512, 512)).astype(np.float32)}
    data = encode_layer_set(GridLayersMessage(0.0, "uav1", g, noise), {"a": "float16", "b": "float16"})
    assert len(data) < 1_000_000
    back = decode_layer_set(data)
    assert np.abs(back.layers["a"] - noise["a"]).max() <= 100 / 252 / 2 + 1e-3  # uint8: 252 levels
    with pytest.raises(ValueError, match="max_bytes"):
        colors = {n: rng.integers(0, 256, (512, 512, 3), dtype=np.uint8) for n in ("c", "d")}  # 1.5 MB of noise
        encode_layer_set(GridLayersMessage(0.0, "uav1", g, colors))


def test_decode_rejects_with_reason():
    good = msg.encode_cloud(msg.CloudMessage("uav1", 0, PointCloud(np.zeros((10, 3), np.float32), np.zeros(3), 0.0)))
    with pytest.raises(BadMessage, match="not protobuf"):
        msg.decode_cloud(good[: len(good) // 2])
    m = pb.PointCloud()
    m.ParseFromString(good)
    m.points.shape[:] = [11, 3]
    with pytest.raises(BadMessage, match="needs 132 bytes, got 120"):
        msg.decode_cloud(m.SerializeToString())
    m.points.shape[:] = [10, 3]
    m.points.data = np.full((10, 3), np.nan, np.float32).tobytes()
    with pytest.raises(BadMessage, match="not finite"):
        msg.decode_cloud(m.SerializeToString())
    with pytest.raises(BadMessage, match="missing field"):
        msg.decode_cloud(b"")


def test_frame_and_state_decoders_reject_bad_poses_and_intrinsics():
    img = np.zeros((4, 6, 3), np.uint8)
    good = msg.encode_frame(msg.FrameMessage("uav1", 1, CameraFrame(img, Pose(), CameraIntrinsics(5, 5, 2, 2, 6, 4), 0.0)))
    m = pb.CameraFrame()
    m.ParseFromString(good)
    m.pose.orientation.w = 2.0  # not a unit quaternion
    with pytest.raises(BadMessage, match="orientation"):
        msg.decode_frame(m.SerializeToString())
    m.ParseFromString(good)
    m.intrinsics.fx = 0.0
    with pytest.raises(BadMessage, match="fx"):
        msg.decode_frame(m.SerializeToString())
    s = pb.VehicleState()
    s.ParseFromString(msg.encode_state(msg.State(0.0, "uav1", Pose())))
    s.pose.position.x = float("nan")
    with pytest.raises(BadMessage, match="position"):
        msg.decode_state(s.SerializeToString())
