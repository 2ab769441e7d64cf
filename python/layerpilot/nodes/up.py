"""`layerpilot up`: start a mission's nodes as processes, show their status, restart the dead, stop cleanly.

``up`` itself opens the first Zenoh session, so it holds the well-known endpoint for the
whole mission: nodes that die and restart always find the same place to connect to.
With ``bus.security`` on (the default) that session is the mission's hub: a router that admits
only the users whose credentials ``up`` writes into the secrets directory and enforces the
mission's allow-list (bus/security.py); each node gets its own ``--credentials`` file.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

from layerpilot.missionfile import load_mission, resolve

RESTART_DELAY = 1.0  # s before the first restart; doubled after each failure in a row
MAX_RESTART_DELAY = 30.0  # s
HEALTHY_AFTER = 60.0  # s alive: the node's failures in a row start over
MAX_FAILURES = 5  # failures in a row after which a node is reported failed and left down
CHECK_PERIOD = 0.2  # s between looks at the nodes (dead ones, the end of --duration)
SILENT_AFTER = 30.0  # s without a status line (nodes print one every 2 s): the whole process is stuck
STOP_GRACE = 15.0  # s between SIGTERM and SIGKILL (links, then the rest, the map server last: Supervisor.stop)
DELIVERY_GRACE = 0.5  # s for the hub to deliver what the stopped nodes sent last, before the map server stops


@dataclass
class NodeProcess:
    """One node: its command line, its process, and what it last said about itself."""

    name: str
    argv: list[str]
    proc: subprocess.Popen | None = None
    restarts: int = 0
    status: dict = field(default_factory=dict)
    started: float = 0.0
    failures_in_a_row: int = 0
    restart_at: float = 0.0  # monotonic time of the next restart (backoff)
    failed: str = ""  # set once the node is given up on: its last error line
    heard_at: float = 0.0  # monotonic time of its last status line
    log_path: Path | None = None

    def start(self, log_dir: Path) -> None:
        log_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = log_dir / (self.name.replace("/", "-") + ".log")
        with open(self.log_path, "a") as log:
            self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE, stderr=log, text=True,
                                         start_new_session=True)  # Ctrl-C reaches `up` only; `up` stops the nodes
        self.started = self.heard_at = time.monotonic()
        threading.Thread(target=self._read, args=(self.proc,), daemon=True).start()

    def _read(self, proc: subprocess.Popen) -> None:
        for line in proc.stdout:
            try:
                self.status = json.loads(line)
            except json.JSONDecodeError:
                continue
            self.heard_at = time.monotonic()

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def last_error(self) -> str:
        """The node's last word: its failure status line, else the last line of its log."""
        if self.status.get("status") == "failed":
            return str(self.status.get("error", ""))
        try:
            lines = [ln for ln in self.log_path.read_text(errors="replace").splitlines() if ln.strip()]
        except (OSError, AttributeError):
            return ""
        return lines[-1] if lines else ""

    def line(self) -> str:
        state = "FAILED" if self.failed else "alive" if self.alive() else "DOWN"
        if self.failed:
            return f"{self.name:<16} {state:<6} restarts={self.restarts} last error: {self.failed}"
        info = {k: v for k, v in self.status.items() if k not in ("node", "vehicle", "status")}
        pid = self.proc.pid if self.proc is not None else "-"
        return f"{self.name:<16} {state:<5} pid={pid} restarts={self.restarts} " + " ".join(f"{k}={v}" for k, v in info.items())


def node_commands(mission_path: Path, vehicles: list[str], endpoint: str | None,
                  secrets=None, resume: bool = False, clock_start: float = 0.0,
                  mission_id: str = "", frames: str = "sim", ros2: bool = False,
                  frame_dir: Path | None = None) -> list[NodeProcess]:
    """map-server first (one for all vehicles), then per vehicle sim, link, depth, decide (``frames``:
    ``camera`` runs `layerpilot camera` in the sim node's place, for a real camera; ``photos`` runs only
    `layerpilot camera` and depth: a photo folder is the camera and the telemetry, nothing flies); with
    ``secrets`` (bus.security.MissionSecrets) each node logs in with its own credentials file;
    ``resume``: the decide nodes continue the saved survey (``decide --resume``); ``clock_start``:
    where the sim and link nodes' stamps start on the mission clock (``--clock-start``);
    ``mission_id``: this run's, so that a restarted decide node continues what it saved; ``ros2``: one
    `layerpilot ros2` bridge per vehicle as well (``[ros2] enabled``); ``frame_dir``: where the sim nodes
    write frame.json (``sim --write-frame``: the map snapshot's directory, so the run's map has its place)."""
    from layerpilot.bus.security import node_user

    base = [sys.executable, "-m", "layerpilot.cli"]
    common = ["--config", str(mission_path)] + (["--endpoint", endpoint] if endpoint else [])

    def login(role: str, vehicle: str | None = None) -> list[str]:
        return [] if secrets is None else ["--credentials", str(secrets.credentials_file(node_user(role, vehicle)))]

    sim_frame = [] if frame_dir is None else ["--write-frame", str(frame_dir)]
    nodes = [NodeProcess("map-server", base + ["map-server"] + common + login("map-server"))]
    for v in vehicles:
        roles = ("camera", "depth") if frames == "photos" else (frames, "link", "depth", "decide")
        for role in roles + (("ros2",) if ros2 else ()):
            own = {"decide": ["--mission-id", mission_id] + (["--resume"] if resume else []),
                   "sim": ["--clock-start", repr(clock_start)] + sim_frame,
                   "link": ["--clock-start", repr(clock_start)]}
            argv = base + [role, "--vehicle", v] + common + login(role, v) + own.get(role, [])
            nodes.append(NodeProcess(f"{role}/{v}", argv))
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
        """Restart every node that died, with exponential backoff; give up after MAX_FAILURES in a row."""
        events = []
        now = time.monotonic()
        for n in self.nodes:
            if n.alive() and now - n.heard_at > SILENT_AFTER and not self.stopping.is_set():
                events.append(f"{n.name} STALLED: no status line for {now - n.heard_at:.0f} s; killing it")
                n.proc.kill()
                n.proc.wait()
            if n.proc is None or n.alive() or n.failed or self.stopping.is_set():
                continue
            if n.restart_at == 0.0:  # just found dead
                code = n.proc.returncode
                n.failures_in_a_row = 1 if now - n.started >= HEALTHY_AFTER else n.failures_in_a_row + 1
                error = n.last_error()
                if n.failures_in_a_row >= MAX_FAILURES:
                    n.failed = error or f"exit code {code}"
                    events.append(f"{n.name} FAILED: exited with {code} {n.failures_in_a_row} times in a row; "
                                  f"last error: {n.failed}")
                    continue
                delay = min(RESTART_DELAY * 2 ** (n.failures_in_a_row - 1), MAX_RESTART_DELAY)
                n.restart_at = now + delay
                events.append(f"{n.name} exited with {code} ({error}); restarting in {delay:.0f} s")
            elif now >= n.restart_at:
                n.restart_at = 0.0
                n.restarts += 1
                n.start(self.log_dir)
        return events

    def stop(self) -> None:
        """SIGTERM the link nodes first and wait for them (each commands the mission's end action,
        RTL by default, and waits at most ``link.end_timeout`` <= 12 s for the autopilot's answer,
        while the simulated vehicles still run); then every other node but the map server (each
        finishes its current message); the map server last, so every cloud a depth node sent is in
        its final snapshot (and in a recording's replay). Each stage SIGKILLs what is left after
        STOP_GRACE."""
        self.stopping.set()
        links = [n for n in self.nodes if n.name.startswith("link/")]
        servers = [n for n in self.nodes if n.name == "map-server"]
        self._stop_group(links)
        self._stop_group([n for n in reversed(self.nodes) if n not in links and n not in servers])
        time.sleep(DELIVERY_GRACE)
        self._stop_group(servers)

    @staticmethod
    def _stop_group(nodes: list[NodeProcess]) -> None:
        for n in nodes:
            if n.alive():
                n.proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + STOP_GRACE
        for n in nodes:
            if n.proc is None:
                continue
            try:
                n.proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                n.proc.kill()
                n.proc.wait()


def frames_of(source: str) -> str:
    """Who makes a mission's frames: ``sim``, ``photos`` (a folder played as the camera) or ``camera``."""
    from layerpilot.nodes.camera import source_kind

    if source == "sim":
        return "sim"
    return "photos" if source_kind(source) == "photos" else "camera"


def up(mission: str | None, *, endpoint: str | None = None, status_every: float = 2.0,
       duration: float | None = None, log_dir: str | Path = "runs/logs", secrets_dir: str | Path | None = None,
       operator_can_save: bool = False, resume: bool = False, record: str | Path | None = None,
       record_ros2: str = "off") -> int:
    """``secrets_dir``: where the bus credentials go (default ``<log_dir>/../bus-secrets``);
    ``record``: an MCAP file every bus message is written to (bus/recording.py), with ROS 2 channels
    beside or instead of the protobuf ones (``record_ros2``: ros2.recording.MODES); ``resume``: continue
    the survey saved in ``decide.state`` after a battery swap (refused before anything starts if a
    vehicle has none)."""
    from layerpilot.bus.security import open_hub
    from layerpilot.bus.session import open_session
    from layerpilot.mission.resume import clock_after, set_aside, state_file
    from layerpilot.nodes.runner import bus_config

    path = resolve(mission)
    m = load_mission(path)  # refuse a bad file before anything starts
    clock = 0.0  # mission time when the vehicles' clocks read 0: the survey's saved time when it resumes
    if resume:  # before anything starts: a survey to continue must exist
        missing = [v for v in m.vehicles if not m.decide.state or not state_file(m.decide.state, v).exists()]
        if missing:
            raise ValueError(f"--resume: no saved survey state for {', '.join(missing)} in decide.state "
                             f"({m.decide.state!r})")
        clock = clock_after(m.decide.state, m.vehicles).start  # read once: restarted nodes keep this start
    # a new survey keeps a saved one aside (<vehicle>.json.bak) rather than overwrite it; done here, before
    # any node starts, so the warning below is true however soon the run ends
    saved = [] if resume or not m.decide.state else \
        [v for v in m.vehicles if set_aside(state_file(m.decide.state, v)) is not None]
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    bus, secrets = bus_config(m.bus, endpoint), None
    if bus.security:  # the hub: holds the well-known endpoint, checks every login, enforces the allow-list
        secrets_dir = Path(log_dir).parent / "bus-secrets" if secrets_dir is None else Path(secrets_dir)
        session, secrets = open_hub(bus, secrets_dir, m.vehicles, bus.operator_can_save or operator_can_save,
                                    photos=frames_of(m.camera.source) == "photos",
                                    ros2=(m.ros2.domain_id, m.ros2.namespace) if m.ros2.enabled else None)
    else:
        session = open_session(bus)  # bus.security = false: an open peer bus, for debugging only
    mission_id = uuid.uuid4().hex[:12]
    # the simulated vehicles' EKF origin beside the map's snapshots (camera_only: another autopilot's, unknown)
    frame_dir = Path(m.map_server.snapshot).parent if m.map_server.snapshot and not m.camera_only else None
    sup = Supervisor(node_commands(path.resolve(), m.vehicles, endpoint, secrets, resume, clock, mission_id,
                                   frames_of(m.camera.source), m.ros2.enabled, frame_dir),
                     Path(log_dir))
    recorder = None
    if record is not None:  # listening before any node starts: the recording misses no cloud
        from layerpilot.bus.recording import Recorder
        from layerpilot.ros2.recording import recording_options

        try:
            recorder = Recorder(session, record, path.read_text(), **recording_options(record_ros2, m.ros2))
        except OSError as exc:
            session.close()
            raise OSError(f"--record: {exc}") from None
    sup.start()
    print(f"layerpilot up: {path.name}: {len(sup.nodes)} nodes for {', '.join(m.vehicles)}; "
          f"node logs in {log_dir}/; mission {mission_id}"
          + (f", resumed at mission time {clock:.1f} s" if resume else ""), flush=True)
    if saved:
        print(f"layerpilot up: warning: a new survey (no --resume): the surveys saved in decide.state for "
              f"{', '.join(saved)} are kept as <vehicle>.json.bak (rename back and `up --resume` to continue "
              "them)", flush=True)
    print(f"layerpilot up: bus secured: operator credentials in {secrets.credentials_file('operator')}"
          if secrets else "layerpilot up: bus.security = false: ANY process that reaches "
          f"{bus.endpoint} can publish waypoints", flush=True)
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
        recorded = recorder.stop() if recorder is not None else {}
        if recorded:
            print("layerpilot up: recorded " + json.dumps(recorded), flush=True)
        session.close()
    print("layerpilot up: stopped " + ", ".join(f"{n.name} ({n.proc.returncode})" for n in sup.nodes), flush=True)
    if recorded.get("error"):
        print(f"layerpilot up: error: the recording is incomplete: {recorded['error']}; "
              f"{recorded['dropped']} messages dropped", file=sys.stderr, flush=True)
        return 1
    return 0
