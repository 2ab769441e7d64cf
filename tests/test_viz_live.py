"""A short live mission with `up --record` and `view --web` side by side, as a user would run them:
a real headless Chromium shows the web viewer, the MCAP file is read back with the `mcap` library, and
`replay` rebuilds the live map server's final map voxel for voxel and asks another behavior."""

from __future__ import annotations

import json
import re
import time
from collections import Counter

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from rerun.chunk import RrdReader

from layerpilot.bus.session import free_endpoint
from layerpilot.eval.replay import replay
from layerpilot.map import VoxelMap
from browser import Chromium
from conftest import SMALL_MISSION_NODES, cli_process, free_tcp_port, start_up, stop_up, wait_for

SCHEMAS = {"camera": "layerpilot.CameraFrame", "cloud": "layerpilot.PointCloud", "pose": "layerpilot.VehicleState",
           "layers": "layerpilot.LayerSet", "decision": "layerpilot.Decision", "waypoint": "layerpilot.Waypoint",
           "state": "layerpilot.MissionState",
           **{f"health/{n}": "layerpilot.NodeHealth" for n in ("sim", "link", "depth", "decide", "map-server")}}


def scene_pixels(png: bytes) -> tuple[int, int]:
    """(forest-green pixels, area-of-interest-yellow pixels) of a screenshot: the map's voxels and the AOI outline."""
    rgb = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1].astype(int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(((g > r + 15) & (g > b + 15)).sum()), int(((r > 180) & (g > 180) & (b < 80)).sum())


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """The mission flown live with a recording, the web view and a browser on it; what each left behind."""
    tmp = tmp_path_factory.mktemp("live")
    ep, logs = free_endpoint(), tmp / "logs"
    mission = tmp / "mission.toml"
    mission.write_text(f"""
vehicles = ["uav1"]
speed = 3.0
mavlink_port = {free_tcp_port()}
[map_server]
resolution = 1.0
layers_rate = 0.5
window = [-128.0, -128.0, 256, 256]
snapshot = "{tmp / 'map.ot'}"
snapshot_period = 1000.0
""" + SMALL_MISSION_NODES.replace("[link]\n", "[link]\nend_action = \"loiter\"\nend_timeout = 1.0\n"))
    up, lines = start_up(mission, ep, logs, "--record", str(tmp / "mission.mcap"))
    browser = None
    try:
        creds = tmp / "bus-secrets" / "operator.json"
        wait_for(creds.exists, "the operator's credentials")
        with cli_process("view", "--config", str(mission), "--endpoint", ep, "--credentials", str(creds), "--web",
                         "--web-port", str(free_tcp_port()), "--grpc-port", str(free_tcp_port()),
                         "--save", str(tmp / "view.rrd")) as view, \
                cli_process("record", str(tmp / "joined.mcap"), "--config", str(mission), "--endpoint", ep,
                            "--credentials", str(creds)) as record:
            ready = json.loads(view.stdout.readline())
            assert json.loads(record.stdout.readline())["status"] == "ready"
            browser = Chromium(960, 600)  # small: SwiftShader draws every pixel on the CPU
            browser.open(ready["url"])
            shot, green, yellow = b"", 0, 0
            end = time.monotonic() + 120  # the viewer's WebAssembly compiles on a software GPU: seconds
            while time.monotonic() < end and (green < 1000 or yellow < 200):
                time.sleep(1.0)
                shot = browser.screenshot()
                green, yellow = scene_pixels(shot)
            title = browser.evaluate("document.title + ' ' + document.querySelectorAll('canvas').length")
            (tmp / "view.png").write_bytes(shot)
            view.send_signal(2)  # Ctrl-C: the view finishes its .rrd, the recorder its file
            record.send_signal(2)
            out, err = view.communicate(timeout=30)
            joined = json.loads(record.communicate(timeout=30)[0].strip().splitlines()[-1])
        stopped = json.loads(out.strip().splitlines()[-1])
    finally:
        if browser is not None:
            browser.close()
        stop_up(up)
    recorded = next(json.loads(ln.split("recorded ", 1)[1]) for ln in lines if "layerpilot up: recorded" in ln)
    return {"dir": tmp, "title": title, "green": green, "yellow": yellow, "view": stopped, "recorded": recorded,
            "view_log": err, "joined": joined}


def test_web_viewer_shows_the_mission_in_a_real_browser(live):
    assert live["title"] == "Rerun Viewer 1"  # the viewer's page loaded and made its canvas
    assert live["green"] >= 1000, "no forest voxels on the screenshot"
    assert live["yellow"] >= 200, "no area-of-interest outline on the screenshot"
    heard, logged = live["view"]["heard"], live["view"]["logged"]
    assert live["view"]["rejected"] == 0, live["view_log"]
    for topic in ("pose", "camera", "layers", "decision"):
        assert heard[topic] > 0 and logged[topic] > 0, topic
    assert logged["voxels"] > 0


def test_view_shows_every_nodes_health_and_the_decisions_aggregate_layers(live):
    """Through the hub's allow-list as the operator: each node's health key, and A0..A3 asked of the decide
    node, are in the view (its .rrd): rates, drops and rejections per node, the aggregates over the layers."""
    logged = live["view"]["logged"]
    nodes = ("sim", "link", "depth", "decide", "map-server")
    assert all(logged[f"health/{n}"] >= 2 for n in nodes), logged
    assert logged["aggregates"] >= 1
    rows: Counter[str] = Counter()
    for chunk in RrdReader(live["dir"] / "view.rrd").stream():
        rows[chunk.entity_path] += chunk.num_rows
    series = ["/health/map-server/dropped", "/health/map-server/rate/inserted", "/health/depth/rate/clouds",
              "/health/decide/rate/decisions", "/health/link/rate/poses", "/health/sim/rate/frames",
              "/health/decide/loops/decide", "/health/decide/inputs/pose"]
    series += [f"/health/{n}/rejected" for n in nodes if n != "sim"] + [f"/layers/A{i}" for i in range(4)]
    assert not [e for e in series if rows[e] == 0], sorted(e for e in rows if e.startswith(("/health", "/layers")))
    with open(live["dir"] / "mission.mcap", "rb") as f:  # `up --record` holds the nodes' health too
        decide = [json.loads(decoded.status) for _, _, _, decoded in make_reader(
            f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=["layerpilot/uav1/health/decide"])]
    assert len(decide) >= 2 and decide[-1]["decisions"] >= 1
    assert decide[-1]["aggregates_asked"] >= logged["aggregates"]  # answered to the view's questions


def test_recording_is_read_back_by_the_mcap_library(live):
    counts, schemas = Counter(), {}
    with open(live["dir"] / "mission.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            counts[channel.topic] += 1
            schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            assert type(decoded).__name__ == schema.name.split(".")[1]
        mission = reader.get_summary()  # the index and footer were written: a complete file
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert mission is not None
    assert "vehicles" in metadata["layerpilot"]["mission"]
    for topic, name in SCHEMAS.items():
        assert schemas[f"layerpilot/uav1/{topic}"] == (name, "protobuf", "protobuf")
    assert dict(counts) == live["recorded"]["messages"]  # every message the recorder heard, none lost or doubled
    assert live["recorded"]["dropped"] == live["recorded"]["rejected"] == 0


def test_record_joining_the_mission_holds_a_contiguous_part_of_it(live):
    """`layerpilot record` joined after `up` started and stopped before it: per key, its messages are one
    unbroken run of what `up --record` holds (nothing lost or reordered in between)."""
    def by_key(path) -> dict[str, list[bytes]]:
        out: dict[str, list[bytes]] = {}
        with open(path, "rb") as f:
            for _, channel, message in make_reader(f).iter_messages():
                out.setdefault(channel.topic, []).append(message.data)
        return out

    full, joined = by_key(live["dir"] / "mission.mcap"), by_key(live["dir"] / "joined.mcap")
    assert joined and {len(v) for v in joined.values()} != {0}
    assert {k: len(v) for k, v in joined.items()} == live["joined"]["messages"]
    for key in ("layerpilot/uav1/cloud", "layerpilot/uav1/decision", "layerpilot/uav1/layers"):  # lossless topics
        part, whole = joined[key], full[key]  # (the empty map's first layer sets are equal bytes: try every start)
        assert any(whole[i:i + len(part)] == part for i in range(len(whole) - len(part) + 1)), key


def test_replay_map_only_gives_the_live_map_voxel_for_voxel(live):
    out = live["dir"] / "replay-map"
    with cli_process("replay", str(live["dir"] / "mission.mcap"), "--map-only", "--out", str(out)) as p:
        stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 0, stderr
    clouds = int(re.search(r"\((\d+) clouds\)", stdout).group(1))
    assert clouds == live["recorded"]["messages"]["layerpilot/uav1/cloud"] > 0
    with open(live["dir"] / "mission.mcap", "rb") as f:  # the live map server's own counts, as it published them
        health = [json.loads(decoded.status) for _, _, _, decoded in make_reader(f, decoder_factories=[
            DecoderFactory()]).iter_decoded_messages(topics=["layerpilot/uav1/health/map-server"])]
    assert health and health[-1]["inserted"] > 0
    assert health[-1]["dropped"] == 0, (f"the live map server dropped {health[-1]['dropped']} clouds (queue full "
                                        f"under load): its map cannot equal the replay's; {health[-1]}")
    live_map, replayed = VoxelMap.load(live["dir"] / "map.ot"), VoxelMap.load(out / "map.ot")
    box = np.array([-500.0, -500.0, -100.0]), np.array([500.0, 500.0, 300.0])
    a, b = live_map.voxels(*box, min_occupancy=0.0), replayed.voxels(*box, min_occupancy=0.0)
    assert len(a) > 1000 and len(a) == len(b)
    for name in ("centers", "occupancy", "color", "last_seen", "min_distance"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert live_map.to_bytes() == replayed.to_bytes()


def test_replay_behavior_writes_its_choices_and_the_comparison_picture(live):
    out = live["dir"] / "replay-exploration"
    result = replay(live["dir"] / "mission.mcap", out, behavior="exploration")  # the command's function
    assert result.damage == "" and result.unknown_schemas == {} and result.rejected == 0
    decisions = [json.loads(line) for line in (out / "decisions.jsonl").read_text().splitlines()]
    chosen = [d for d in decisions if "waypoint" in d]
    assert len(chosen) >= 5 and len(chosen) == len(decisions)
    times = [d["time"] for d in decisions]
    assert times == sorted(times) and min(np.diff(times)) >= 2.0 - 1e-6  # one choice per layer tick (0.5 Hz)
    assert len(result.flown) == live["recorded"]["messages"]["layerpilot/uav1/decision"] > 0
    flown_xy = np.array([f["waypoint"][:2] for f in result.flown])
    far = [np.min(np.hypot(*(flown_xy - d["waypoint"][:2]).T)) > 3.0 for d in chosen]
    assert any(far)  # another behavior: places the flown pilot never chose
    picture = cv2.imread(str(out / "replay.png"))
    cyan = ((picture[..., 0] > 200) & (picture[..., 1] > 200) & (picture[..., 2] < 80)).sum()  # BGR: the choices
    assert picture.shape[0] > 300 and cyan > 100
