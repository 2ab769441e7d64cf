"""`layerpilot sim|depth|decide|link` run their bus nodes as real processes: ready line, status, SIGTERM."""

from __future__ import annotations

import ctypes
import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import cli_process
from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.cli import main as cli_main

SMALL_SIM = "[sim]\nframe_rate_hz = 4.0\n[sim.world]\nsize = 100.0\n[sim.camera]\nwidth = 160\nheight = 120\n"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "layerpilot.cli", *args], capture_output=True, text=True, timeout=60)


def mission(tmp_path: Path, text: str = SMALL_SIM) -> str:
    path = tmp_path / "mission.toml"
    path.write_text(text)
    return str(path)


def test_sim_node_serves_mavlink_and_publishes_frames_for_the_given_mission_time(tmp_path):
    """On a mission clock started at 100 s (a resumed survey): the vehicle's clock runs 0..3 s, the frames
    and the status say 100..103 s."""
    ep = free_endpoint()
    with cli_process("sim", "--config", mission(tmp_path), "--endpoint", ep, "--mavlink", "tcp:127.0.0.1:0",
                     "--duration", "3", "--speed", "1", "--clock-start", "100") as proc:
        ready = json.loads(proc.stdout.readline())
        assert ready["status"] == "ready" and ready["node"] == "sim" and ready["vehicle"] == "uav1"
        assert ready["mavlink"][0].startswith("tcp:127.0.0.1:0 -> 127.0.0.1:")
        assert ready["camera"] == "160x120 at 4 Hz" and ready["seed"] == 0 and ready["trees"] > 0
        frames: list[msg.FrameMessage] = []
        with open_session(BusConfig(endpoint=ep)) as client:
            client.declare_subscriber(Keys("uav1").camera,
                                      lambda s: frames.append(msg.decode_frame(s.payload.to_bytes())))
            out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    last = json.loads(out.strip().splitlines()[-1])
    assert last["status"] == "stopped" and last["time"] == 103.0 and last["frames"] == 13  # t = 0, 0.25, ..., 3
    assert frames, "no camera frame reached a peer on the bus"
    stamps = [f.frame.stamp for f in frames]
    assert stamps == sorted(stamps) and 100.0 <= stamps[0] and stamps[-1] == 103.0, stamps
    assert frames[-1].frame.image.shape == (120, 160, 3) and frames[-1].frame.depth.shape == (120, 160)


def test_a_bad_clock_start_is_refused_naming_the_flag(tmp_path, capsys):
    assert cli_main(["link", "--config", mission(tmp_path), "--endpoint", free_endpoint(),
                     "--clock-start", "-5"]) == 2
    assert "--clock-start: mission clock start: expected finite seconds >= 0, got -5.0" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["0", "-5", "nan", "inf"])
def test_up_refuses_a_duration_that_is_not_a_positive_number_of_seconds(value, tmp_path, capsys):
    """Before anything starts: `up --duration 0` would start every node and stop them at once."""
    with pytest.raises(SystemExit) as stopped:
        cli_main(["up", "--mission", mission(tmp_path), "--duration", value, "--log-dir", str(tmp_path / "logs")])
    assert stopped.value.code == 2 and f"argument --duration: must be finite seconds > 0, got {value}" in capsys.readouterr().err
    assert not (tmp_path / "logs").exists()


def test_sim_node_rejects_a_bad_rate_naming_the_flag(tmp_path):
    done = run("sim", "--config", mission(tmp_path), "--endpoint", free_endpoint(), "--mavlink", "tcp:127.0.0.1:0",
               "--rate", "0")
    assert done.returncode == 2 and "--rate must be in [0.01, 100.0], got 0.0" in done.stderr
    assert "Traceback" not in done.stderr


def test_sim_node_does_not_write_the_frame_of_another_autopilot(tmp_path):
    """camera_only: the vehicle is ArduPilot's or PX4's SITL, whose EKF origin this node cannot know."""
    done = run("sim", "--config", mission(tmp_path, "camera_only = true\n" + SMALL_SIM), "--endpoint", free_endpoint(),
               "--write-frame", str(tmp_path / "run"))
    assert done.returncode == 2 and "--write-frame: with camera_only = true" in done.stderr
    assert not (tmp_path / "run").exists()


def test_sim_node_reports_a_busy_mavlink_port(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        url = f"tcp:127.0.0.1:{s.getsockname()[1]}"
        done = run("sim", "--config", mission(tmp_path), "--endpoint", free_endpoint(), "--mavlink", url)
    assert done.returncode == 2 and f"MAVLink {url}" in done.stderr


TGKILL = {"x86_64": 234, "aarch64": 131}  # syscall numbers


def sigterm_a_worker_thread(pid: int) -> None:
    """SIGTERM one of the process's other threads (Zenoh's, ours), as kill(2) may hand it to any thread."""
    tids = [int(t) for t in os.listdir(f"/proc/{pid}/task") if int(t) != pid]
    libc = ctypes.CDLL(None, use_errno=True)
    assert libc.syscall(TGKILL[os.uname().machine], pid, max(tids), signal.SIGTERM) == 0, ctypes.get_errno()


@pytest.mark.parametrize("to_thread", [False, True], ids=["to-process", "to-a-worker-thread"])
@pytest.mark.parametrize("role", ["sim", "depth", "decide", "link"])
def test_node_exits_cleanly_on_sigterm(role, to_thread, tmp_path):
    """Every node: ready, status lines, then SIGTERM -> a last 'stopped' line and exit 0.

    The signal may land on any thread; Python handles it on the main thread, so a main
    thread blocked without a timeout would never exit (it did, ~1 in 10 missions). The link
    node is stopped while it still waits for an autopilot (nothing serves its URL).
    """
    with socket.socket() as s:  # a port nobody serves
        s.bind(("127.0.0.1", 0))
        nobody = f"tcp:127.0.0.1:{s.getsockname()[1]}"
    extra = {"sim": ["--mavlink", "tcp:127.0.0.1:0"], "link": ["--mavlink", nobody]}.get(role, [])
    with cli_process(role, "--config", mission(tmp_path), "--endpoint", free_endpoint(), "--status-every", "0.2",
                     *extra) as proc:
        lines = [json.loads(proc.stdout.readline())]
        # the link says `ready` only once an autopilot answers (nobody does here): `connecting` until then
        assert lines[0]["status"] == ("connecting" if role == "link" else "ready") and lines[0]["node"] == role
        lines.append(json.loads(proc.stdout.readline()))  # a status line: the node is running
        assert "status" not in lines[1] and lines[1]["node"] == role
        sigterm_a_worker_thread(proc.pid) if to_thread else proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert json.loads(out.strip().splitlines()[-1])["status"] == "stopped"


def test_unknown_vehicle_is_refused(tmp_path):
    done = run("depth", "--config", mission(tmp_path), "--vehicle", "uav9", "--endpoint", free_endpoint())
    assert done.returncode == 2 and "uav9" in done.stderr and "uav1" in done.stderr
