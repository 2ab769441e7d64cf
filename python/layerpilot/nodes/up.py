"""`layerpilot up`: start a mission's nodes as processes, show their status, restart the dead, stop cleanly.

``up`` itself opens the first Zenoh session, so it holds the well-known endpoint for the
whole mission: nodes that die and restart always find the same place to connect to.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from layerpilot.nodes.mission import load_mission, resolve

RESTART_DELAY = 1.0  # s
CHECK_PERIOD = 0.2  # s between looks at the nodes (dead ones, the end of --duration)
STOP_GRACE = 15.0  # s between SIGTERM and SIGKILL


@dataclass
class NodeProcess:
    """One node: its command line, its process, and what it last said about itself."""

    name: str
    argv: list[str]
    proc: subprocess.Popen | None = None
    restarts: int = 0
    status: dict = field(default_factory=dict)
    started: float = 0.0
    exit_codes: list[int] = field(default_factory=list)

    def start(self, log_dir: Path) -> None:
        log_dir.mkdir(parents=True, exist_ok=True)
        with open(log_dir / (self.name.replace("/", "-") + ".log"), "a") as log:
            self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE, stderr=log, text=True,
                                         start_new_session=True)  # Ctrl-C reaches `up` only; `up` stops the nodes
        self.started = time.monotonic()
        threading.Thread(target=self._read, args=(self.proc,), daemon=True).start()

    def _read(self, proc: subprocess.Popen) -> None:
        for line in proc.stdout:
            try:
                self.status = json.loads(line)
            except json.JSONDecodeError:
                continue

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def line(self) -> str:
        state = "alive" if self.alive() else "DOWN"
        info = {k: v for k, v in self.status.items() if k not in ("node", "vehicle", "status")}
        pid = self.proc.pid if self.proc is not None else "-"
        return f"{self.name:<16} {state:<5} pid={pid} restarts={self.restarts} " + " ".join(f"{k}={v}" for k, v in info.items())


def node_commands(mission_path: Path, vehicles: list[str], endpoint: str | None) -> list[NodeProcess]:
    """map-server first (one for all vehicles), then per vehicle sim, link, depth, decide."""
    base = [sys.executable, "-m", "layerpilot.cli"]
    common = ["--config", str(mission_path)] + (["--endpoint", endpoint] if endpoint else [])
    nodes = [NodeProcess("map-server", base + ["map-server"] + common)]
    for v in vehicles:
        for role in ("sim", "link", "depth", "decide"):
            nodes.append(NodeProcess(f"{role}/{v}", base + [role, "--vehicle", v] + common))
    return nodes


class Supervisor:
    def __init__(self, nodes: list[NodeProcess], log_dir: Path) -> None:
        self.nodes = nodes
        self.log_dir = log_dir
        self.stopping = threading.Event()

    def start(self) -> None:
        for n in self.nodes:
            n.start(self.log_dir)

    def check(self) -> list[str]:
        """Restart every node that died (after RESTART_DELAY); returns what happened."""
        events = []
        for n in self.nodes:
            if n.proc is not None and not n.alive() and not self.stopping.is_set():
                code = n.proc.returncode
                if time.monotonic() - n.started < RESTART_DELAY:
                    continue
                n.exit_codes.append(code)
                n.restarts += 1
                events.append(f"{n.name} exited with {code}; restarting")
                n.start(self.log_dir)
        return events

    def stop(self) -> None:
        """SIGTERM every node (each finishes its current message), SIGKILL what is left after STOP_GRACE."""
        self.stopping.set()
        for n in reversed(self.nodes):
            if n.alive():
                n.proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + STOP_GRACE
        for n in self.nodes:
            if n.proc is None:
                continue
            try:
                n.proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                n.proc.kill()
                n.proc.wait()


def up(mission: str | None, *, endpoint: str | None = None, status_every: float = 2.0,
       duration: float | None = None, log_dir: str | Path = "runs/logs") -> int:
    from layerpilot.bus.session import open_session
    from layerpilot.nodes.runner import bus_config

    path = resolve(mission)
    m, tables = load_mission(path)  # refuse a bad file before anything starts
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    session = open_session(bus_config(tables, endpoint))  # the hub: holds the well-known endpoint
    sup = Supervisor(node_commands(path.resolve(), m.vehicles, endpoint), Path(log_dir))
    sup.start()
    print(f"layerpilot up: {path.name}: {len(sup.nodes)} nodes for {', '.join(m.vehicles)}; "
          f"node logs in {log_dir}/", flush=True)
    t0 = time.monotonic()
    next_status, end = t0 + status_every, math.inf if duration is None else t0 + duration
    try:
        while not stop.wait(CHECK_PERIOD):  # restarts and the end do not wait for the next status block
            for e in sup.check():
                print(e, flush=True)
            now = time.monotonic()
            if now >= next_status or now >= end:
                next_status += status_every
                print(f"--- t={now - t0:.0f}s", flush=True)
                for n in sup.nodes:
                    print(n.line(), flush=True)
            if now >= end:
                break
    finally:
        sup.stop()
        session.close()
    print("layerpilot up: stopped " + ", ".join(f"{n.name} ({n.proc.returncode})" for n in sup.nodes), flush=True)
    return 0
