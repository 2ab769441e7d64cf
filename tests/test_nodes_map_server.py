"""The map server on real Zenoh sessions over loopback: insert, query, publish, drop oldest, snapshot, SIGTERM."""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.layerset import decode_layer_set, to_column_layers
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.geometry import PointCloud
from layerpilot.map import VoxelMap
from layerpilot.missionfile import Mission
from layerpilot.mission.map_service import MapServiceConfig
from layerpilot.nodes.map_server import MapServer
from conftest import cli_process, wait_for

K = Keys("uav1")


def ground_cloud(stamp: float, z: float = 0.0, n: int = 40) -> msg.CloudMessage:
    """A flat square of ground 20 m x 20 m at height z, seen from 10 m above its centre."""
    xs, ys = np.meshgrid(np.linspace(-9.9, 9.9, n), np.linspace(-9.9, 9.9, n))
    pts = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, z)], 1).astype(np.float32)
    return msg.CloudMessage("uav1", int(stamp), PointCloud(pts, np.array([0.0, 0.0, z + 10.0]), stamp))


def get_one(session, selector: str):
    replies = list(session.get(selector, timeout=10.0))
    assert len(replies) == 1, selector
    r = replies[0]
    if r.ok is None:
        raise ValueError(r.err.payload.to_bytes().decode())
    return r.ok.payload.to_bytes()


@pytest.fixture
def bus():
    ep = free_endpoint()
    server_session = open_session(BusConfig(endpoint=ep))
    client = open_session(BusConfig(endpoint=ep))
    yield server_session, client
    client.close()
    server_session.close()


def test_insert_query_publish_and_snapshot_reload(bus, tmp_path):
    server_session, client = bus
    cfg = Mission(map_server=MapServiceConfig(resolution=0.5, layers_rate=5.0, window=(-10.0, -10.0, 40, 40),
                          snapshot=str(tmp_path / "map.ot"), snapshot_period=0.5))
    server = MapServer(server_session, cfg)
    server.start()
    published = []
    sub = client.declare_subscriber(K.layers, lambda s: published.append(s.payload.to_bytes()))
    try:
        clouds = client.declare_publisher(K.cloud, congestion_control=zenoh.CongestionControl.BLOCK)
        # Publish only once the server's subscription has reached the client, or puts are lost.
        wait_for(lambda: clouds.matching_status.matching, "the map server's cloud subscription")
        for i in range(5):
            clouds.put(msg.encode_cloud(ground_cloud(float(i + 1))))
        wait_for(lambda: server.service.clouds_inserted == 5, "5 inserts")
        assert server.service.points_inserted == 5 * 1600

        ls = decode_layer_set(get_one(client, K.service("layers") + "?x=-10;y=-10;w=40;h=40"))
        cl = to_column_layers(ls)
        assert ls.geometry.shape == (40, 40) and ls.stamp == 5.0
        assert cl.observed.all()  # the whole 20 m x 20 m window is ground
        np.testing.assert_allclose(cl.elevation, 0.5, atol=1e-3)  # top face of the voxel holding z = 0
        np.testing.assert_allclose(cl.last_seen, 5.0, atol=1e-3)

        part = decode_layer_set(get_one(client, K.service("layers") + "?x=0;y=0;w=4;h=2;layers=elevation"))
        assert list(part.layers) == ["elevation"] and part.layers["elevation"].shape == (2, 4)

        stats = pb.MapStats.FromString(get_one(client, K.service("stats")))
        assert stats.clouds_inserted == 5 and stats.leaves > 1600 and stats.resolution == 0.5

        vox = pb.VoxelSet.FromString(get_one(client, K.service("voxels") + "?min=-2,-2,-1;max=2,2,1"))
        assert tuple(vox.centers.shape) == (64, 3)  # 8 x 8 ground voxels of 0.5 m

        with pytest.raises(ValueError, match="w, h"):
            get_one(client, K.service("layers") + "?w=0")
        with pytest.raises(ValueError, match="min"):
            get_one(client, K.service("voxels"))

        wait_for(lambda: len(published) >= 2, "published layer sets")
        assert decode_layer_set(published[-1]).geometry.shape == (40, 40)
        wait_for(lambda: server.snapshots_written >= 1, "a periodic snapshot")
        save = pb.SaveReply.FromString(get_one(client, K.service("save")))
        assert Path(save.path) == (tmp_path / "map.ot").resolve() and save.bytes > 0
    finally:
        sub.undeclare()
        server.stop()

    reloaded = MapServer(server_session, cfg)  # a restart reloads the snapshot
    assert reloaded.map.stats()["leaves"] == server.map.stats()["leaves"]
    assert reloaded.map.column_layers(-10, -10, 40, 40).observed.all()


def test_full_queue_drops_oldest_and_stays_bounded(bus):
    server_session, client = bus
    server = MapServer(server_session, Mission(map_server=MapServiceConfig(resolution=0.5, queue_size=3, snapshot="")))
    # no worker yet: every cloud waits in the queue, so the drops are deterministic
    for i in range(10):
        server._enqueue(ground_cloud(float(i)), K.cloud)
    assert len(server.queue) == 3 and server.queue.dropped == 7 and server.queue.received == 10
    assert [server.queue.get().cloud.stamp for _ in range(3)] == [7.0, 8.0, 9.0]  # the newest survive, oldest first
    server._enqueue(ground_cloud(10.0), K.cloud)
    server.start()
    wait_for(lambda: server.service.clouds_inserted == 1, "the insert")
    assert server.service.last_stamp == 10.0 and len(server.queue) == 0
    server.stop()


def test_clouds_still_queued_at_stop_are_in_the_last_snapshot(bus, tmp_path):
    """Stopping the map server inserts what it received before its last snapshot: nothing received is lost."""
    server_session, client = bus
    snapshot = tmp_path / "map.ot"
    server = MapServer(server_session, Mission(map_server=MapServiceConfig(resolution=0.5, queue_size=8,
                                                                           snapshot=str(snapshot))))
    for i in range(3):  # never started: every cloud still waits in the queue when it stops
        server._enqueue(ground_cloud(float(i)), K.cloud)
    server.stop()
    assert server.service.clouds_inserted == 3 and server.service.last_stamp == 2.0 and len(server.queue) == 0
    assert VoxelMap.load(snapshot).stats()["leaves"] == server.map.stats()["leaves"] > 0


def test_daemon_process_serves_and_exits_on_sigterm(tmp_path):
    ep = free_endpoint()
    snap = tmp_path / "map.ot"
    mission = tmp_path / "mission.toml"
    mission.write_text("[map_server]\nresolution = 0.5\nwindow = [-10.0, -10.0, 40, 40]\n")
    with cli_process("map-server", "--config", str(mission), "--endpoint", ep, "--snapshot", str(snap),
                     "--status-every", "0.2") as proc:
        assert json.loads(proc.stdout.readline())["status"] == "ready"
        with open_session(BusConfig(endpoint=ep)) as client:
            time.sleep(0.5)
            client.put(K.cloud, msg.encode_cloud(ground_cloud(1.0)))
            client.put(K.cloud, b"\x00garbage")

            def inserted() -> bool:
                return pb.MapStats.FromString(get_one(client, K.service("stats"))).clouds_inserted == 1

            wait_for(inserted, "the daemon's insert")
            proc.send_signal(signal.SIGTERM)
            out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    last = json.loads(out.strip().splitlines()[-1])
    assert last["inserted"] == 1 and last["rejected"] == 1
    assert "not protobuf" in err  # logged once with the reason
    assert VoxelMap.load(snap).column_layers(-10, -10, 40, 40).observed.all()  # final snapshot on exit


def test_bench_bus_runs_small():
    from layerpilot.bench.bus import run

    r = run(seconds=0.3, rate=10.0, width=32, height=24, queries=3, window=64)
    assert r["clouds_sent"] == 3 and r["clouds_inserted"] + r["clouds_dropped"] == 3
    assert r["layer_set_bytes"] > 0 and r["layer_query_ms_median"] > 0


def test_every_query_gets_an_answer(bus):
    """Selectors that match several services or none, and windows off the map, get replies (errors say why)."""
    server_session, client = bus
    server = MapServer(server_session, Mission(map_server=MapServiceConfig(resolution=1.0, snapshot="")))
    server.start()
    try:
        time.sleep(0.3)
        for x in ("1e300", "1e19", "9.3e18"):
            replies = list(client.get(K.service("layers") + f"?x={x}", timeout=10.0))
            assert len(replies) == 1 and replies[0].err is not None
            assert "x:" in replies[0].err.payload.to_bytes().decode()
        replies = list(client.get("layerpilot/uav1/map/*", timeout=10.0))
        assert len(replies) >= 1  # one per service that answered; save says it has no snapshot path
        assert any(r.ok is not None for r in replies)
        assert server.rejects.total >= 3
    finally:
        server.stop()


@pytest.mark.parametrize("damage", ["half", "100 bytes", "empty", "garbled header", "garbage inside"])
def test_a_damaged_snapshot_never_stops_the_map_server(bus, tmp_path, damage, caplog):
    """The newest snapshot is damaged: it is moved aside with an ERROR and the previous good one is served."""
    from layerpilot.map.snapshots import SnapshotStore

    server_session, _ = bus
    path = tmp_path / "map.ot"
    store = SnapshotStore(path, keep=3)
    good = VoxelMap(0.5)
    c = ground_cloud(1.0).cloud
    good.insert(c.points, c.origin, stamp=1.0)
    store.save(good)
    bigger = VoxelMap(0.5)
    for z in (0.0, 3.0):
        c = ground_cloud(2.0, z).cloud
        bigger.insert(c.points, c.origin, stamp=2.0)
    store.save(bigger)
    data = path.read_bytes()
    damaged = {"half": data[: len(data) // 2], "100 bytes": data[:100], "empty": b"",
               "garbled header": b"# Octomap OcTree file\nid nonsense\n" + data[40:],
               "garbage inside": data[:len(data) // 2] + bytes(rng_bytes(4096)) + data[len(data) // 2 + 4096:]}[damage]
    path.write_bytes(damaged)
    mission = Mission(map_server=MapServiceConfig(resolution=0.5, snapshot=str(path)))
    with caplog.at_level("ERROR"):
        server = MapServer(server_session, mission)
    assert server.map.stats()["leaves"] == good.stats()["leaves"]  # the previous good snapshot, not a part
    assert list(tmp_path.glob("map.ot.damaged-*")), list(tmp_path.iterdir())
    assert any("map.ot" in r.getMessage() for r in caplog.records if r.levelname == "ERROR")


def rng_bytes(n: int) -> bytes:
    return np.random.default_rng(3).integers(0, 256, n, dtype=np.uint8).tobytes()


def test_all_snapshots_damaged_starts_empty_with_an_error(bus, tmp_path, caplog):
    server_session, _ = bus
    path = tmp_path / "map.ot"
    path.write_bytes(b"\x00" * 100)
    with caplog.at_level("ERROR"):
        server = MapServer(server_session, Mission(map_server=MapServiceConfig(resolution=0.5, snapshot=str(path))))
    assert server.map.stats()["leaves"] == 0
    assert any("starting with an empty map" in r.getMessage() for r in caplog.records)
