"""Supervised loops: an unexpected error is logged once per kind with its traceback and counted, the loop goes
on; a loop that cannot go on, or stalls, fails the node; `up` restarts a failing node with backoff and gives
up after MAX_FAILURES in a row, reporting its last error line."""

from __future__ import annotations

import logging
import signal
import subprocess
import sys
import time

import pytest

from layerpilot.nodes import supervise
from layerpilot.nodes.supervise import Supervisor
from conftest import free_tcp_port, wait_for


def test_an_error_is_logged_once_per_kind_counted_and_the_loop_goes_on(caplog):
    sup = Supervisor(logging.getLogger("test.supervise"))
    calls = []

    def iteration() -> bool:
        calls.append(1)
        if len(calls) in (2, 3):
            raise OverflowError("int too large")  # what a 1e-320 grid resolution once did
        if len(calls) == 4:
            raise KeyError("x")
        return len(calls) < 10

    with caplog.at_level(logging.ERROR):
        sup.start("worker", iteration).join(5)
    assert len(calls) == 10 and not sup.failed.is_set()
    assert sup.errors == {"worker: OverflowError": 2, "worker: KeyError": 1}
    logged = [r.getMessage() for r in caplog.records]
    assert len(logged) == 2 and all("Traceback" in m for m in logged)  # once per kind, with the traceback
    assert sup.status()["errors"] == 3 and "worker" not in sup.status()["loops"]  # ended normally


def test_a_loop_that_cannot_go_on_fails_the_node():
    sup = Supervisor(logging.getLogger("test.supervise"))
    sup.start("always", lambda: 1 / 0).join(5)
    assert sup.failed.is_set() and "50 failures in a row" in sup.failure and "ZeroDivisionError" in sup.failure
    sup2 = Supervisor(logging.getLogger("test.supervise"))

    def oom() -> bool:
        raise MemoryError("no more")
    sup2.start("alloc", oom).join(5)
    assert sup2.failed.is_set() and sup2.failure == "alloc: MemoryError: no more"


def test_a_stalled_loop_is_reported(monkeypatch):
    monkeypatch.setattr(supervise, "STALL_AFTER", 0.2)
    sup = Supervisor(logging.getLogger("test.supervise"))
    sup.start("stuck", lambda: time.sleep(1.0) or False)
    wait_for(lambda: sup.stalled() == ["stuck"], "the stall")
    sup.heard("layerpilot/uav1/pose")
    assert "layerpilot/uav1/pose" in sup.status()["inputs"]


def test_up_restarts_a_failing_node_with_backoff_then_reports_it_failed(tmp_path):
    port = free_tcp_port()  # a MAVLink port where nobody listens: the link node cannot connect
    mission = tmp_path / "m.toml"
    mission.write_text(f'camera_only = true\n[map_server]\nsnapshot = ""\n[link.link]\nurl = "tcp:127.0.0.1:{port}"\n'
                       'connect_timeout_s = 0.5\n')
    from layerpilot.bus.session import free_endpoint
    up = subprocess.Popen([sys.executable, "-m", "layerpilot.cli", "up", "--mission", str(mission), "--endpoint",
                           free_endpoint(), "--log-dir", str(tmp_path / "logs"), "--duration", "120",
                           "--status-every", "1"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    for line in up.stdout:  # until up gives the link node up (or ends at --duration)
        lines.append(line)
        if "link/uav1 FAILED" in line:
            up.send_signal(signal.SIGTERM)
    up.wait(timeout=60)
    out = "".join(lines)
    assert up.returncode == 0, out
    restarts = [line for line in out.splitlines() if line.startswith("link/uav1 exited with")]
    delays = [int(line.rsplit("restarting in ", 1)[1].split()[0]) for line in restarts]
    assert delays == [1, 2, 4, 8], out  # exponential backoff
    failed = [line for line in out.splitlines() if "link/uav1 FAILED" in line]
    assert failed and "5 times in a row" in failed[0] and "last error:" in failed[0], out
    assert "connect" in failed[0].lower() or "mavlink" in failed[0].lower(), failed[0]
