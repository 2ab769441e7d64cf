"""`layerpilot up` flies the scripted baselines live, each for at least 60 mission seconds, with the pilot
reporting waypoints reached and the vehicle's track passing through them; survey-refly goes on to its
next flights over the gaps."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.session import free_endpoint
from layerpilot.mission.build import build_pilot
from layerpilot.missionfile import load_mission
from conftest import free_tcp_port, operator_session, start_up, stop_up

K = Keys("uav1")


@pytest.mark.parametrize("pattern", ["lawnmower", "orbit", "survey", "survey-side", "orbit-rings", "survey-refly"])
def test_up_flies_a_scripted_pattern_live(tmp_path, pattern):
    if pattern == "survey-refly":  # over a 40 m disc: one line, then the next flights over the gaps
        from test_baselines import small_refly
        pattern = str(small_refly(tmp_path))
    ep = free_endpoint()
    mission = tmp_path / "mission.toml"
    mission.write_text(f"""
speed = 6.0
mavlink_port = {free_tcp_port()}
[map_server]
snapshot = ""
[depth]
source = "ground_truth"
stride = 4
[decide]
behavior = "{pattern}"
[sim]
frame_rate_hz = 2.0
[sim.camera]
width = 160
height = 120
""")
    expected = build_pilot(load_mission(mission).core)  # the waypoints the pattern must fly, in order
    up, lines = start_up(mission, ep, tmp_path / "logs")
    client = None
    try:
        time.sleep(1.0)
        client = operator_session(ep, tmp_path / "logs")
        waypoints: dict[int, msg.Waypoint] = {}
        states: list[msg.MissionState] = []
        poses: list[msg.State] = []
        lock = threading.Lock()

        def on_waypoint(sample) -> None:
            w = msg.decode_waypoint(sample.payload.to_bytes())
            with lock:
                waypoints.setdefault(w.seq, w)
        subs = [client.declare_subscriber(K.waypoint, on_waypoint),
                client.declare_subscriber(K.state, lambda s: states.append(msg.decode_mission_state(s.payload.to_bytes()))),
                client.declare_subscriber(K.pose, lambda s: poses.append(msg.decode_state(s.payload.to_bytes())))]
        end = time.monotonic() + 150
        enough = len(expected.pattern) + 1 if "refly" in pattern else 2
        while not (waypoints and states and states[-1].waypoints_reached >= enough
                   and poses and poses[-1].stamp - min(w.stamp for w in waypoints.values()) >= 60.0):
            assert up.poll() is None, "up exited:\n" + "".join(lines[-30:])
            assert time.monotonic() < end, f"{pattern}: too slow:\n" + "".join(lines[-30:])
            time.sleep(0.2)
        for s in subs:
            s.undeclare()
        with lock:
            flown = [waypoints[k] for k in sorted(waypoints)]
        # the pattern's own waypoints, in its order, with its heading and speed
        for w, want in zip(flown, expected.pattern):
            np.testing.assert_allclose(w.position, want[:3], atol=1e-6)
            assert w.yaw == pytest.approx(want[3]) and w.speed == pytest.approx(expected.cruise_speed)
        if "refly" in pattern:  # past the pattern: planned over the gaps, reached like the pattern's own
            assert states[-1].waypoints_reached > len(expected.pattern) and len(flown) > len(expected.pattern)
        # reached means flown through: the track passes within the arrival radius of each reached waypoint
        track = np.array([p.position for p in poses])
        for w in flown[: states[-1].waypoints_reached]:
            assert np.min(np.hypot(*(track[:, :2] - w.position[:2]).T)) <= 3.0 + 1e-6, w
    finally:
        if client is not None:
            client.close()
        stop_up(up)
    assert up.returncode == 0, "".join(lines[-20:])
    # issue 14 item 2: `up` stops the link first, while the simulated vehicle still flies, and the
    # link commands the mission's end action (RTL) and sees it acknowledged before it exits
    link_log = (tmp_path / "logs" / "link-uav1.log").read_text()
    assert link_log.count("mission end: RTL acknowledged (COMMAND_ACK accepted, mode RTL)") == 1, link_log[-3000:]
