"""Shared test fixtures: paths to the reference data beside the project."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

import pytest

ROOT_DIR = Path(__file__).resolve().parents[1]
SHARED = ROOT_DIR.parent / "shared"
OCTOMAP_DATA = SHARED / "data" / "octomap"


@pytest.fixture(scope="session")
def octomap_data() -> Path:
    assert (OCTOMAP_DATA / "scan.dat.bz2").is_file(), f"reference data missing: {OCTOMAP_DATA}"
    return OCTOMAP_DATA


def free_tcp_port() -> int:
    """A TCP port nobody listens on right now (for a mission's simulated MAVLink vehicles)."""
    return _free_port(socket.SOCK_STREAM)


def free_udp_port() -> int:
    """A UDP port nobody uses right now (MAVLink over UDP, MAVProxy's outputs)."""
    return _free_port(socket.SOCK_DGRAM)


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(cond, what: str, timeout: float = 20.0) -> None:
    """Poll ``cond`` until it holds; a bound on waiting for other threads/processes, not a speed check."""
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def start_up(mission: Path, endpoint: str, log_dir: Path, *extra: str) -> tuple[subprocess.Popen, list[str]]:
    """`layerpilot up` (with ``extra`` options) as a child process in its own process group, and the list
    its output lines go to."""
    up = subprocess.Popen([sys.executable, "-m", "layerpilot.cli", "up", "--mission", str(mission),
                           "--endpoint", endpoint, "--status-every", "1", "--log-dir", str(log_dir), *extra],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(up.stdout), daemon=True).start()
    return up, lines


def operator_session(endpoint: str, log_dir: Path, timeout: float = 20.0):
    """The operator's session on the bus of a `start_up` mission: `up` writes the operator's credentials
    into <log_dir>/../bus-secrets/ and then opens its hub; retried until both are there."""
    from layerpilot.bus.security import JoinRefused, open_node_session
    from layerpilot.bus.session import BusConfig

    creds = Path(log_dir).parent / "bus-secrets" / "operator.json"
    end = time.monotonic() + timeout
    while True:
        try:
            return open_node_session(BusConfig(endpoint=endpoint), creds)
        except (JoinRefused, FileNotFoundError, ValueError):
            if time.monotonic() > end:
                raise
            time.sleep(0.2)


def stop_up(up: subprocess.Popen) -> None:
    """SIGTERM, as Ctrl-C would; SIGKILL the whole group only if it is still there after 30 s."""
    if up.poll() is None:
        up.send_signal(signal.SIGTERM)
        try:
            up.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(up.pid, signal.SIGKILL)
            up.wait()


@contextlib.contextmanager
def cli_process(*args: str) -> Iterator[subprocess.Popen]:
    """`layerpilot ARGS` as a child process with text pipes; killed on the way out if still running."""
    proc = subprocess.Popen([sys.executable, "-m", "layerpilot.cli", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


# The node tables of the small missions the `layerpilot up` tests fly (ground-truth depth, 160x120 camera)
SMALL_MISSION_NODES = """
[depth]
source = "ground_truth"
stride = 4
[decide]
behavior = "balanced"
[link]
takeoff_altitude = 30.0
[sim]
frame_rate_hz = 2.0
[sim.camera]
width = 160
height = 120
"""


def balanced_behavior(folder: Path, name: str, head: str = "", tail: str = "") -> str:
    """The shipped balanced preset with top-level keys before it (e.g. the paper's hops in metres) and
    tables after it (e.g. retargeting off), written to ``folder / name``: a live test's fixed variant."""
    path = folder / name
    path.write_text(head + (ROOT_DIR / "config" / "behaviors" / "balanced.toml").read_text() + tail)
    return str(path)
