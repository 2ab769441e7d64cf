"""`layerpilot up` with a real drone's sensors (`sim.sensors = "consumer"`): the autopilot reports EKF poses
metres and degrees off, the camera's clock runs behind the telemetry's, the images are noisy and blurred;
the depth node refines its pairs' poses from the images and says so in its health, the map grows, and the
decide node keeps deciding."""

from __future__ import annotations

import time

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.session import free_endpoint
from conftest import free_tcp_port, operator_session, start_up, stop_up

K = Keys("uav1")


def test_a_consumer_sensor_mission_refines_maps_and_keeps_deciding(tmp_path):
    ep = free_endpoint()
    mission = tmp_path / "mission.toml"
    mission.write_text(f"""
speed = 3.0
mavlink_port = {free_tcp_port()}
[map_server]
snapshot = ""
[depth]
source = "stereo"
[decide]
behavior = "balanced"
[sim]
frame_rate_hz = 1.0
sensors = "consumer"
[sim.camera]
width = 320
height = 240
""")
    logs = tmp_path / "logs"
    up, lines = start_up(mission, ep, logs)
    operator = None
    health: list[dict] = []
    decisions: list[msg.Decision] = []
    try:
        operator = operator_session(ep, logs)
        subs = [operator.declare_subscriber(K.health("depth"),
                                            lambda s: health.append(msg.decode_health(s.payload.to_bytes()).status)),
                operator.declare_subscriber(K.decision,
                                            lambda s: decisions.append(msg.decode_decision(s.payload.to_bytes())))]
        end = time.monotonic() + 240
        while True:
            assert up.poll() is None and time.monotonic() < end, "".join(lines[-20:])
            replies = list(operator.get(K.service("stats"), timeout=5.0))
            stats = pb.MapStats.FromString(replies[0].ok.payload.to_bytes()) if replies and replies[0].ok else None
            last = health[-1] if health else {}  # the depth node's newest status (it may lag the map's count)
            if (stats is not None and stats.clouds_inserted >= 5 and last.get("refined", 0) >= 5
                    and last.get("clouds", 0) >= 5 and len(decisions) >= 4):
                break
            time.sleep(1.0)
        assert last["refined"] >= 5 and last["clouds"] >= 5, last
        assert "time_offset_pairs" in last, last  # the camera clock's offset is being estimated
        assert last["height_registered"] >= 1, last  # clouds are fitted to the flight's earlier ones
        assert last["surface_checked"] >= 1, last  # and compared with the last clouds before they reach the map
        seqs = [d.seq for d in decisions]
        assert seqs == sorted(seqs) and len(set(seqs)) >= 4  # new decisions kept coming
        for s in subs:
            s.undeclare()
    finally:
        if operator is not None:
            operator.close()
        stop_up(up)
    assert up.returncode == 0, "".join(lines[-20:])
