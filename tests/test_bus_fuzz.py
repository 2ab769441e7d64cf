"""Thousands of malformed payloads: every decoder rejects each with a reason, the map server keeps serving."""

from __future__ import annotations

import time

import numpy as np
import pytest
import zenoh

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.layerset import GridLayersMessage, decode_layer_set, encode_layer_set, to_column_layers
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.geometry import CameraFrame, CameraIntrinsics, PointCloud, Pose
from layerpilot.grid import GridGeometry
from layerpilot.missionfile import Mission
from layerpilot.mission.depth_service import DepthServiceConfig
from layerpilot.mission.map_service import MapServiceConfig
from layerpilot.nodes.map_server import MapServer

rng = np.random.default_rng(11)
GOOD = {
    msg.decode_cloud: msg.encode_cloud(msg.CloudMessage("uav1", 1, PointCloud(
        rng.normal(size=(50, 3)).astype(np.float32), np.zeros(3), 1.0, rng.integers(0, 256, (50, 3), dtype=np.uint8)))),
    msg.decode_frame: msg.encode_frame(msg.FrameMessage("uav1", 1, CameraFrame(
        rng.integers(0, 256, (8, 10, 3), dtype=np.uint8), Pose(), CameraIntrinsics(10, 10, 5, 4, 10, 8), 1.0,
        np.ones((8, 10), np.float32)))),
    msg.decode_state: msg.encode_state(msg.State(1.0, "uav1", Pose())),
    msg.decode_waypoint: msg.encode_waypoint(msg.Waypoint(1.0, "uav1", 1, np.ones(3))),
    msg.decode_decision: msg.encode_decision(msg.Decision(1.0, "uav1", 1, np.ones(3), 0.5, (msg.Term("a", 1, 1, 1),))),
    msg.decode_mission_state: msg.encode_mission_state(msg.MissionState(1.0, "uav1", "survey")),
    msg.decode_health: msg.encode_health(msg.NodeHealth("uav1", "link", 3.5, {"poses": 7, "phase": "flying"})),
    decode_layer_set: encode_layer_set(GridLayersMessage(1.0, "uav1", GridGeometry(0, 0, 1, 16, 8), {
        "observed": rng.random((8, 16)) > 0.5, "elevation": rng.random((8, 16)).astype(np.float32),
        "last_seen": rng.random((8, 16)), "color": rng.integers(0, 256, (8, 16, 3), dtype=np.uint8)})),
}


def mutations(good: bytes, n: int):
    """Random bytes, truncations, bit flips, and arrays with wrong sizes or NaN, in equal parts."""
    for i in range(n):
        kind = i % 4
        if kind == 0:
            yield rng.integers(0, 256, int(rng.integers(1, 200)), dtype=np.uint8).tobytes()
        elif kind == 1:
            yield good[: int(rng.integers(0, len(good)))]
        elif kind == 2:
            b = bytearray(good)
            for _ in range(int(rng.integers(1, 6))):
                b[int(rng.integers(0, len(b)))] ^= 1 << int(rng.integers(0, 8))
            yield bytes(b)
        else:
            yield _corrupt_array(good)


def _corrupt_array(good: bytes) -> bytes:
    """Re-serialize with one Array field made inconsistent (shape, dtype, NaN) — parses fine, must not pass."""
    for cls in (pb.PointCloud, pb.CameraFrame, pb.LayerSet):
        m = cls()
        try:
            m.ParseFromString(good)
        except Exception:
            continue
        arrays = [m.points] if cls is pb.PointCloud else [m.image] if cls is pb.CameraFrame else \
            [layer.data for layer in m.layers]
        if not arrays or not arrays[0].dtype:
            continue
        a = arrays[int(rng.integers(0, len(arrays)))]
        choice = int(rng.integers(0, 3))
        if choice == 0:
            a.shape[0] += 1
        elif choice == 1:
            a.dtype = "float64" if a.dtype != "float64" else "int64"
        else:
            m.stamp = float("nan")
        return m.SerializeToString()
    m = pb.Waypoint()
    m.position.x = float("nan")
    return m.SerializeToString()


@pytest.mark.parametrize("decode", list(GOOD), ids=lambda f: f.__name__)
def test_every_decoder_rejects_or_returns_valid(decode):
    assert decode(GOOD[decode]) is not None
    kinds: dict[str, int] = {}
    accepted = 0
    for payload in mutations(GOOD[decode], 2000):
        try:
            decode(payload)
            accepted += 1  # e.g. a bit flip inside a pixel: still a well-formed message
        except BadMessage as exc:
            assert exc.reason
            kinds[exc.kind] = kinds.get(exc.kind, 0) + 1
    assert sum(kinds.values()) >= 1000, kinds
    assert accepted < 1000


INSERT_KINDS = {"outside the area", "too costly", "map full", "insert failed"}  # the map server's, after decoding


def test_map_server_survives_thousands_of_bad_clouds():
    ep = free_endpoint()
    server_session = open_session(BusConfig(endpoint=ep))
    client = open_session(BusConfig(endpoint=ep))
    server = MapServer(server_session, Mission(map_server=MapServiceConfig(resolution=0.5, snapshot="", queue_size=10_000)))
    server.start()
    try:
        time.sleep(0.5)
        key = Keys("uav1").cloud
        bad = [p for p in mutations(GOOD[msg.decode_cloud], 3000)]
        expected_rejects = 0
        pub = client.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)  # lose nothing
        for p in bad:
            try:
                msg.decode_cloud(p)
            except BadMessage:
                expected_rejects += 1
            pub.put(p)
        client.put(key, GOOD[msg.decode_cloud])
        # a mutation that decodes may still be refused at insertion (an origin bit-flipped out of the area)
        decoding = lambda: sum(n for k, n in server.rejects.by_kind().items() if k not in INSERT_KINDS)  # noqa: E731
        end = time.monotonic() + 60
        while decoding() < expected_rejects and time.monotonic() < end:
            time.sleep(0.05)
        assert decoding() == expected_rejects
        assert server.queue.received == len(bad) + 1 - expected_rejects
        kinds = server.rejects.by_kind()
        assert {"not protobuf", "bad size"} <= set(kinds), kinds
        reply = list(client.get(Keys("uav1").service("stats"), timeout=10))[0]
        assert pb.MapStats.FromString(reply.ok.payload.to_bytes()).messages_rejected >= expected_rejects
    finally:
        server.stop()
        client.close()
        server_session.close()


def test_decide_and_depth_nodes_survive_thousands_of_bad_messages():
    from layerpilot.nodes.decide import DecideNode
    from layerpilot.nodes.depth import DepthNode

    ep = free_endpoint()
    node_session, client = open_session(BusConfig(endpoint=ep)), open_session(BusConfig(endpoint=ep))
    decide = DecideNode(node_session, "uav1", Mission())
    depth = DepthNode(node_session, "uav1", Mission(depth=DepthServiceConfig(source="ground_truth")))
    decide.start()
    depth.start()
    try:
        time.sleep(0.5)
        k = Keys("uav1")
        expected = {}
        cells = Mission().map_server.window[2] * Mission().map_server.window[3]  # decide's cap: the mission's window
        layers_ok = lambda p: to_column_layers(decode_layer_set(p, max_cells=cells))  # noqa: E731 - what decide accepts
        for key, good, decode in ((k.layers, GOOD[decode_layer_set], layers_ok), (k.pose, GOOD[msg.decode_state], msg.decode_state),
                                  (k.camera, GOOD[msg.decode_frame], msg.decode_frame),
                                  ("layerpilot/uav2/decision", GOOD[msg.decode_decision], msg.decode_decision)):
            bad = []
            for p in mutations(good, 1000):
                try:
                    decode(p)
                except BadMessage:
                    bad.append(p)
            pub = client.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)  # lose nothing
            for p in bad:
                pub.put(p)
            pub.undeclare()
            expected[key] = len(bad)
        want_decide = expected[k.layers] + expected[k.pose] + expected["layerpilot/uav2/decision"]
        want_depth = expected[k.camera] + expected[k.pose]  # depth hears the pose too (the camera clock)
        end = time.monotonic() + 60
        while (decide.rejects.total < want_decide or depth.rejects.total < want_depth) and time.monotonic() < end:
            time.sleep(0.05)
        time.sleep(0.5)  # nothing more may arrive
        assert decide.rejects.total == want_decide and depth.rejects.total == want_depth
        assert want_decide > 2000
        # still working: a good frame with depth becomes a cloud
        client.put(k.camera, GOOD[msg.decode_frame])
        while depth.clouds < 1 and time.monotonic() < end:
            time.sleep(0.05)
        assert depth.clouds == 1
    finally:
        decide.stop()
        depth.stop()
        client.close()
        node_session.close()
