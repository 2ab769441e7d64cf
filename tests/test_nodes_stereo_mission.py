"""`layerpilot up` with stereo depth and an MCDM behavior, as the default mission flies: the drone hovers
after take-off with no cloud yet (stereo needs motion), so its first waypoint must come from the empty
map's layer set; then it moves, stereo gives clouds and the map grows."""

from __future__ import annotations

import time

from layerpilot.bus.keys import Keys
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.session import free_endpoint
from conftest import free_tcp_port, operator_session, start_up, stop_up

K = Keys("uav1")


def test_a_stereo_mission_starts_from_an_empty_map(tmp_path):
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
[sim.camera]
width = 160
height = 120
""")
    logs = tmp_path / "logs"
    up, lines = start_up(mission, ep, logs)
    operator = None
    try:
        operator = operator_session(ep, logs)
        end = time.monotonic() + 150
        while True:
            assert up.poll() is None and time.monotonic() < end, "".join(lines[-20:])
            replies = list(operator.get(K.service("stats"), timeout=5.0))
            stats = pb.MapStats.FromString(replies[0].ok.payload.to_bytes()) if replies and replies[0].ok else None
            if stats is not None and stats.clouds_inserted >= 3 and stats.leaves > 0:
                break
            time.sleep(1.0)
    finally:
        if operator is not None:
            operator.close()
        stop_up(up)
    assert up.returncode == 0, "".join(lines[-20:])
