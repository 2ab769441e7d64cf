"""`view --web` on a bus where nothing is said tells so once, on its console and in the page's log; a view
that hears the vehicle says nothing of the kind."""

from __future__ import annotations

import json
import subprocess
import sys
import threading

from rerun.chunk import RrdReader

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.geometry import Pose
from conftest import free_tcp_port

SILENT = ("heard nothing on layerpilot/uav1/** for 5 s: is a mission with vehicle uav1 running (layerpilot up), "
          "and are --endpoint and --credentials right?")


def view(tmp_path, endpoint: str) -> tuple[subprocess.CompletedProcess, list[str]]:
    """`layerpilot view --web` for 7 s; what it printed and the lines of its page's ``log`` (its .rrd)."""
    mission = tmp_path / "mission.toml"
    mission.write_text('vehicles = ["uav1"]\n[bus]\nsecurity = false\n')
    done = subprocess.run([sys.executable, "-m", "layerpilot.cli", "view", "--config", str(mission), "--endpoint",
                           endpoint, "--web", "--web-port", str(free_tcp_port()), "--grpc-port", str(free_tcp_port()),
                           "--save", str(tmp_path / "view.rrd"), "--duration", "7"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    log = [text for chunk in RrdReader(tmp_path / "view.rrd").stream() if chunk.entity_path == "/log"
           for texts in chunk.to_record_batch().column("TextLog:text").to_pylist() for text in texts]
    return done, log


def test_a_view_that_hears_nothing_says_so_once(tmp_path):
    done, log = view(tmp_path, free_endpoint())
    assert json.loads(done.stdout.splitlines()[0])["status"] == "ready"
    assert done.stderr.count("heard nothing") == 1 and f"layerpilot view: warning: {SILENT}\n" in done.stderr
    assert log == [SILENT]


def test_a_view_that_hears_the_vehicle_does_not_warn(tmp_path):
    endpoint = free_endpoint()
    stop = threading.Event()
    with open_session(BusConfig(endpoint=endpoint)) as vehicle:  # the mission's side of the bus: a pose a second
        def talk() -> None:
            t = 0.0
            while not stop.wait(0.5):
                vehicle.put(Keys("uav1").pose, msg.encode_state(msg.State(t, "uav1", Pose.from_euler(0, 0, 0,
                                                                                                    (1.0, 2.0, 30.0)))))
                t += 0.5
        talker = threading.Thread(target=talk, daemon=True)
        talker.start()
        try:
            done, log = view(tmp_path, endpoint)
        finally:
            stop.set()
            talker.join()
    assert json.loads(done.stdout.splitlines()[-1])["heard"]["pose"] > 0
    assert "heard nothing" not in done.stderr and log == []
