"""Recordings: what a real Zenoh session published is in the MCAP file, counted per key and byte for byte;
a damaged or truncated file is read up to the damage with a warning; a foreign schema is skipped and counted."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import threading
import time
from collections import Counter

import numpy as np
import pytest
import zenoh
from mcap.reader import make_reader
from mcap.writer import Writer

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.recording import Recorder, RecordingReader, RecordingWriter
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.geometry import PointCloud, Pose
from conftest import wait_for

K = Keys("uav1")


def bus_messages(n: int) -> list[tuple[str, bytes]]:
    """Poses, clouds, decisions and the decide node's health of one vehicle, as the nodes encode them."""
    rng = np.random.default_rng(0)
    out = []
    for i in range(n):
        out.append((K.pose, msg.encode_state(msg.State(0.1 * i, "uav1", Pose(np.array([i, 0.0, 30.0]))))))
        points = rng.uniform(-20, 20, (500, 3)).astype(np.float32)
        out.append((K.cloud, msg.encode_cloud(msg.CloudMessage("uav1", i, PointCloud(points, np.zeros(3), 0.1 * i)))))
        if i % 5 == 0:
            out.append((K.decision, msg.encode_decision(msg.Decision(0.1 * i, "uav1", i, np.array([i, 1.0, 30.0]),
                                                                     0.5, (), "balanced", np.array([0.0, 2, 30]),
                                                                     f"choice {i}"))))
        if i % 10 == 0:
            out.append((K.health("decide"), msg.encode_health(msg.NodeHealth(
                "uav1", "decide", 0.2 * i, {"decisions": i // 5, "rejected": 0, "loops": {"decide": 0.1}}))))
    return out


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Messages put by one real Zenoh session, recorded by another."""
    path = tmp_path_factory.mktemp("rec") / "bus.mcap"
    ep = free_endpoint()
    with open_session(BusConfig(endpoint=ep)) as recorder_session, open_session(BusConfig(endpoint=ep)) as nodes:
        recorder = Recorder(recorder_session, path, 'vehicles = ["uav1"]\n')
        sent = bus_messages(150)
        publishers = {key: nodes.declare_publisher(key) for key in {k for k, _ in sent}}
        wait_for(lambda: all(p.matching_status.matching for p in publishers.values()), "the recorder's subscription",
                 timeout=60.0)
        # Blocking puts, unlike the nodes' lossy topics: this checks the recorder, not the topics' QoS.
        extra = [("layerpilot/uav1/unknown", b"\x08\x01"),  # not one of ours: rejected, not recorded
                 ("layerpilot/uav1/health/nobody", sent[-1][1])]  # no such node: rejected too
        for key, payload in sent + extra:
            nodes.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)
        wait_for(lambda: sum(recorder.writer.written.values()) + recorder.writer.rejects.total >= len(sent) + 2,
                 "every message at the recorder", timeout=60.0)
        summary = recorder.stop()
    return path, sent, summary


def test_recording_holds_every_published_message_per_key(recorded):
    path, sent, summary = recorded
    with open(path, "rb") as f:
        reader = make_reader(f)
        got = [(channel.topic, message.data, schema.name) for schema, channel, message in reader.iter_messages()]
    assert Counter(k for k, _, _ in got) == Counter(k for k, _ in sent) == Counter(summary["messages"])
    assert [(k, d) for k, d, _ in got] == sent  # in the order published, byte for byte
    assert {k: s for k, _, s in got} == {K.pose: "layerpilot.VehicleState", K.cloud: "layerpilot.PointCloud",
                                         K.decision: "layerpilot.Decision", K.health("decide"): "layerpilot.NodeHealth"}
    assert summary["rejected"] == 2 and summary["dropped"] == 0
    health = [msg.decode_health(d) for k, d, _ in got if k == K.health("decide")]
    assert len(health) == 15 and health[3].status == {"decisions": 6, "rejected": 0, "loops": {"decide": 0.1}}
    assert health[3].uptime == pytest.approx(6.0) and health[3].node == "decide"
    decisions = [msg.decode_decision(d) for k, d, _ in got if k == K.decision]
    assert decisions[2].explanation == "choice 10" and decisions[2].runner_up.tolist() == [0.0, 2.0, 30.0]


def test_truncated_recording_is_read_up_to_the_damage(recorded, tmp_path, caplog):
    path, sent, _ = recorded
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    reader = RecordingReader(cut)
    with caplog.at_level(logging.WARNING, "layerpilot.recording"):
        got = [(m.key, m.data) for m in reader.messages()]
    assert 0 < len(got) < len(sent) and got == sent[: len(got)]  # everything before the damage, nothing after
    assert "cut.mcap: damaged near byte" in reader.damage and f"read {len(got)} messages" in reader.damage
    assert any("damaged" in r.getMessage() for r in caplog.records)


def test_flipped_bytes_stop_reading_at_the_bad_chunk(recorded, tmp_path):
    path, sent, _ = recorded
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 64] = bytes(64)  # zeros inside a compressed chunk: its CRC no longer matches
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    reader = RecordingReader(bad)
    got = [(m.key, m.data) for m in reader.messages()]
    assert len(got) < len(sent) and got == sent[: len(got)]
    assert reader.damage


def test_unknown_schema_is_skipped_and_counted(recorded, tmp_path):
    path, sent, _ = recorded
    mixed = tmp_path / "mixed.mcap"
    with open(mixed, "wb") as f:  # a file another tool wrote: a JSON channel beside ours
        writer = Writer(f)
        writer.start()
        other = writer.register_schema("foxglove.Log", "jsonschema", b"{}")
        foreign = writer.register_channel("/rosout", "json", other)
        ours = writer.register_schema(*_schema_of(path, K.pose))
        pose = writer.register_channel(K.pose, "protobuf", ours)
        for i, (key, payload) in enumerate(m for m in sent if m[0] == K.pose):
            writer.add_message(pose, i, payload, i)
            writer.add_message(foreign, i, b'{"msg": "hello"}', i)
        writer.finish()
    reader = RecordingReader(mixed)
    got = list(reader.messages())
    poses = [p for k, p in sent if k == K.pose]
    assert [m.data for m in got] == poses
    assert reader.unknown_schemas == {"foxglove.Log": len(poses)} and reader.damage == ""


def test_replay_command_warns_about_a_damaged_recording(recorded, tmp_path):
    path, _, _ = recorded
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: len(path.read_bytes()) * 2 // 3])
    proc = subprocess.run([sys.executable, "-m", "layerpilot.cli", "replay", str(cut), "--map-only", "--out",
                           str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "warning:" in proc.stderr and "damaged near byte" in proc.stderr
    assert (tmp_path / "out" / "map.ot").is_file()


def _schema_of(path, key: str) -> tuple[str, str, bytes]:
    with open(path, "rb") as f:
        for schema, channel, _ in make_reader(f).iter_messages():
            if channel.topic == key:
                return schema.name, schema.encoding, schema.data
    raise AssertionError(f"no {key} in {path}")


def test_a_full_disk_fails_the_recording_once_and_counts_what_it_drops(caplog):
    """/dev/full: the writer thread reports ENOSPC once, drops what is queued and everything after it,
    and closing says so in ``error`` instead of raising (``up``'s shutdown and its "stopped" line go on)."""
    sent = bus_messages(150)  # ~1 MB of clouds: several 256 kB chunks, the first flush fails
    writer = RecordingWriter("/dev/full", 'vehicles = ["uav1"]\n')
    with caplog.at_level(logging.ERROR, logger="layerpilot.recording"):
        for key, payload in sent:
            writer.write(key, payload)
        wait_for(lambda: writer.error, "the writer noticing the full disk")
        for key, payload in sent[:20]:  # after the failure: counted, not queued
            writer.write(key, payload)
        writer.close()
    assert "/dev/full: OSError: [Errno 28] No space left on device" in writer.error
    assert not writer._thread.is_alive()
    assert sum(writer.written.values()) + writer.dropped == len(sent) + 20 and writer.dropped >= 20
    assert [r.levelno for r in caplog.records] == [logging.ERROR]  # once, not per message


def test_record_command_to_a_full_disk_or_a_bad_path_says_so_and_fails(tmp_path, capsys):
    """`layerpilot record`: a path it cannot create names the argument; a disk that fills up mid-way
    ends with the stopped summary and one error line, exit 1."""
    from layerpilot.cli import main

    mission = tmp_path / "mission.toml"
    mission.write_text('vehicles = ["uav1"]\n[bus]\nsecurity = false\n')
    ep = free_endpoint()
    assert main(["record", "/dev/full/bus.mcap", "--config", str(mission), "--endpoint", ep]) == 1
    err = capsys.readouterr().err.strip()
    assert err == "layerpilot: error: out: cannot write the recording /dev/full/bus.mcap: /dev/full is not a folder"
    with open_session(BusConfig(endpoint=ep)) as nodes:
        sent = bus_messages(150)
        publisher = nodes.declare_publisher(K.cloud)

        done = threading.Event()

        def publish() -> None:  # however much arrives, the header alone cannot be flushed to /dev/full
            while not publisher.matching_status.matching and not done.is_set():
                time.sleep(0.01)
            for key, payload in sent:
                nodes.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)

        thread = threading.Thread(target=publish, daemon=True)
        thread.start()
        code = main(["record", "/dev/full", "--config", str(mission), "--endpoint", ep, "--duration", "1"])
        done.set()
        thread.join()
    out, err = capsys.readouterr()
    stopped = json.loads(out.strip().splitlines()[-1])
    assert code == 1 and stopped["status"] == "stopped" and "No space left on device" in stopped["error"]
    assert err.strip().splitlines()[-1].startswith("layerpilot record: error: the recording is incomplete: /dev/full")


def test_replay_behavior_of_a_vehicle_the_recording_holds_nothing_of_fails(tmp_path, capsys):
    """A two-vehicle mission whose recording holds only uav1: replaying uav2's behavior says so, exit 2,
    instead of an empty picture."""
    from layerpilot.cli import main

    rec = tmp_path / "uav1-only.mcap"
    with RecordingWriter(rec, 'vehicles = ["uav1", "uav2"]\n') as writer:
        for key, payload in bus_messages(10):
            writer.write(key, payload)
    code = main(["replay", str(rec), "--behavior", "exploration", "--vehicle", "uav2", "--out", str(tmp_path / "o")])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("layerpilot: error:")]
    assert code == 2 and len(err) == 1
    assert err[0].endswith("holds 0 poses and 0 clouds of vehicle 'uav2': nothing to replay --behavior on "
                           "(--vehicle: one of ['uav1', 'uav2'])"), err
    assert not (tmp_path / "o" / "replay.png").exists()
    assert main(["replay", str(rec), "--behavior", "exploration", "--out", str(tmp_path / "o")]) == 0  # uav1's


def test_up_record_to_a_path_it_cannot_create_names_the_flag(tmp_path):
    mission = tmp_path / "mission.toml"
    mission.write_text('vehicles = ["uav1"]\n')
    proc = subprocess.run([sys.executable, "-m", "layerpilot.cli", "up", "--mission", str(mission), "--endpoint",
                           free_endpoint(), "--log-dir", str(tmp_path / "logs"), "--record", "/dev/full/x.mcap"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1 and proc.stdout == ""  # no node started
    assert proc.stderr.strip() == ("layerpilot: error: --record: cannot write the recording /dev/full/x.mcap: "
                                   "/dev/full is not a folder")
