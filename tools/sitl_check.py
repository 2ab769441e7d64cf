"""Check layerpilot against a real ArduCopter SITL binary (issue 14), step by step.

CI cannot build ArduPilot, so the tests fly layerpilot's simulated vehicle; this script is
how the real autopilot is checked during development. It starts the given ``arducopter``
binary with its default parameters (MAVLink on tcp:127.0.0.1:5760, where layerpilot goes;
it watches on the second port, 5762, as a ground station would), runs each step, prints
what it saw and exits 1 on any mismatch::

    .venv/bin/python tools/sitl_check.py /work/sitl/ardupilot/build/sitl/bin/arducopter
    .venv/bin/python tools/sitl_check.py BIN --only ready,cli,script     # some steps

Build the binary as ArduPilot documents it (``./waf configure --board sitl && ./waf copter``;
docs/link.md, "Flying a real ArduPilot or PX4 SITL"). Steps: ``ready`` (cold start until FlightLink.wait_ready), ``cli`` (`layerpilot
link` takeoff/goto/land/rtl, rtl and land on a disarmed vehicle, each warning once),
``script`` (the plain pymavlink ArduCopter script of tests/test_sim_vehicle_ardupilot_script.py
against this SITL and against layerpilot's simulated vehicle, fields side by side),
``up`` (`layerpilot up --mission sitl-camera --duration`: the end commands RTL, the vehicle
comes home and disarms), ``ctrlc`` (the same mission ended by SIGINT), ``reboot``
(MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN on the ground, and the binary killed and restarted while
`link goto` flies), ``battery`` (the pilot's battery return, a swap, `up --resume`). All of them
take about 17 minutes at --speedup 1.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from pymavlink import mavutil

from layerpilot.link.link import LinkError

REPO = Path(__file__).resolve().parent.parent
HOME = "-35.363261,149.165230,584,353"  # ArduPilot's CMAC test field (its locations.txt)
GCS_URL = "tcp:127.0.0.1:5762"  # the SITL's second MAVLink port: this script's eyes
LINK_URL = "tcp:127.0.0.1:5760"  # where layerpilot connects
STEPS = ("ready", "cli", "script", "up", "ctrlc", "reboot", "battery")
mav = mavutil.mavlink


def say(text: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {text}", flush=True)


class Mismatch(AssertionError):
    """What the real autopilot did differs from what layerpilot expects."""


def soon(w: "Watch", predicate, what, seconds: float = 5.0) -> None:
    """``expect`` what the ground station sees within a few seconds (it hears a HEARTBEAT once a second)."""
    try:
        w.wait(predicate, seconds, what)
    except Mismatch:
        pass
    expect(predicate(), f"{what} ({w.state()})")


def expect(ok: bool, what: str) -> None:
    say(("ok    " if ok else "FAIL  ") + what)
    if not ok:
        raise Mismatch(what)


class Sitl:
    """The arducopter process: started in ``workdir`` (its eeprom.bin and logs), wiped or not."""

    def __init__(self, binary: Path, defaults: Path, workdir: Path, speedup: float) -> None:
        self.binary, self.defaults, self.workdir, self.speedup = binary, defaults, workdir, speedup
        self.proc: subprocess.Popen | None = None
        self.started = 0.0

    def start(self, wipe: bool) -> None:
        cmd = [str(self.binary), "--model", "+", "--speedup", f"{self.speedup:g}", "-I0", "--home", HOME,
               "--defaults", str(self.defaults)] + (["-w"] if wipe else [])
        log = open(self.workdir / "arducopter.log", "ab")
        self.proc = subprocess.Popen(cmd, cwd=self.workdir, stdout=log, stderr=subprocess.STDOUT)
        self.started = time.monotonic()
        say(f"arducopter started (pid {self.proc.pid}{', wiped' if wipe else ''}): {' '.join(cmd)}")
        _wait_port(5760, 30.0)

    def boot(self) -> float:
        """SITL boots only once a client connects to 5760: connect, hear a HEARTBEAT, let go (5760 takes one
        client at a time). Seconds from the process start to that HEARTBEAT."""
        conn = mavutil.mavlink_connection(LINK_URL, source_system=255, source_component=190)
        try:
            if conn.wait_heartbeat(timeout=30) is None:
                raise Mismatch("no HEARTBEAT on 5760 within 30 s of connecting")
            return time.monotonic() - self.started
        finally:
            conn.close()

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
            say(f"arducopter pid {self.proc.pid} killed")


def _wait_port(port: int, timeout: float) -> None:
    """Until something listens on ``port`` (without connecting: SITL would take that for its client)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        listening = subprocess.run(["ss", "-Hltn", f"sport = :{port}"], capture_output=True, text=True).stdout
        if listening.strip():
            return
        time.sleep(0.2)
    raise Mismatch(f"nothing listens on 127.0.0.1:{port} after {timeout:.0f} s")


def _closed() -> None:
    raise ConnectionError("connection closed by the SITL")


class Watch:
    """A ground station on the SITL's second port: the latest message of each type, the modes and
    armed states seen, reconnecting after a restart. Only the autopilot's own messages count."""

    def __init__(self) -> None:
        self.last: dict[str, object] = {}
        self.seen_modes: list[str] = []
        self.heartbeats = 0
        self.boots = 0  # times the SITL closed the connection and was connected again: restarts, reboots
        self.uptimes: list[tuple[float, float]] = []  # (when heard, the autopilot's time_boot_ms in s)
        self._last_hb = 0.0
        self._stop = threading.Event()
        self._conn = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _connect(self):
        """A new connection to 5762, retried while it is refused (the SITL boots, or restarts). pymavlink's
        own autoreconnect keeps selecting on the old socket's descriptor, so a silent link is reopened here."""
        while not self._stop.is_set():
            try:
                conn = mavutil.mavlink_connection(GCS_URL, source_system=255, source_component=190, retries=0)
            except OSError:
                time.sleep(0.5)
                continue
            conn.handle_eof = conn.handle_disconnect = _closed  # else it reports EOF and reads on, forever
            return conn
        return None

    def _run(self) -> None:
        self._conn = conn = self._connect()
        next_request, heard = 0.0, time.monotonic()
        while conn is not None and not self._stop.is_set():
            now = time.monotonic()
            if now >= next_request:
                self._request(conn)
                next_request = now + 5.0
            try:
                msg = conn.recv_match(blocking=True, timeout=0.2)
                if msg is None and time.monotonic() - heard > 2.5:
                    raise ConnectionError("no HEARTBEAT for 2.5 s")
            except OSError:  # the SITL went away (closed, or silent): connect again
                conn.close()
                self._conn = conn = self._connect()
                heard, next_request = time.monotonic(), 0.0  # a rebooted SITL forgot the stream rates
                self.last, self.boots = {}, self.boots + 1
                continue
            if msg is None:
                continue
            if msg.get_srcSystem() != 1 or msg.get_srcComponent() != 1:
                continue
            heard = time.monotonic()
            kind = msg.get_type()
            if kind in ("ATTITUDE", "SYSTEM_TIME"):
                self.uptimes.append((heard, msg.time_boot_ms / 1000.0))
            if kind == "HEARTBEAT":
                self._last_hb = now
                self.heartbeats += 1
                mode = mavutil.mode_string_v10(msg)
                if not self.seen_modes or self.seen_modes[-1] != mode:
                    self.seen_modes.append(mode)
            self.last[kind] = msg

    def _request(self, conn) -> None:
        conn.mav.request_data_stream_send(1, 1, mav.MAV_DATA_STREAM_ALL, 5, 1)
        for msg_id in (mav.MAVLINK_MSG_ID_HOME_POSITION, mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN):
            conn.mav.command_long_send(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0, msg_id, 0, 0, 0, 0, 0, 0)

    def send_command(self, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self._conn.mav.command_long_send(1, 1, command, 0, *p)

    def alive(self, within: float = 3.0) -> bool:
        return time.monotonic() - self._last_hb < within

    @property
    def armed(self) -> bool:
        hb = self.last.get("HEARTBEAT")
        return bool(hb and hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)

    @property
    def mode(self) -> str:
        hb = self.last.get("HEARTBEAT")
        return mavutil.mode_string_v10(hb) if hb else "?"

    def local(self) -> tuple[float, float, float]:
        m = self.last["LOCAL_POSITION_NED"]
        return m.x, m.y, m.z

    def relative_alt(self) -> float:
        return self.last["GLOBAL_POSITION_INT"].relative_alt / 1000.0

    def wait(self, predicate, timeout: float, what: str) -> float:
        """Seconds until ``predicate()`` held; a Mismatch naming ``what`` after ``timeout``."""
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            try:
                if predicate():
                    return time.monotonic() - t0
            except KeyError:
                pass
            time.sleep(0.1)
        raise Mismatch(f"{what}: not within {timeout:.0f} s ({self.state()})")

    def state(self) -> str:
        try:
            n, e, d = self.local()
            where = f"NED ({n:.2f}, {e:.2f}, {d:.2f}) rel_alt {self.relative_alt():.2f} m"
        except KeyError:
            where = "no position yet"
        return f"{self.mode} {'ARMED' if self.armed else 'disarmed'}, {where}"

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        if self._conn is not None:
            self._conn.close()


def layerpilot(*args: str, timeout: float = 300.0) -> tuple[int, list[str], list[str], float]:
    """Run ``layerpilot ARGS``; (exit code, stdout lines, stderr lines, seconds); its output printed indented."""
    cmd = [str(Path(sys.executable).with_name("layerpilot")), *args]
    say("$ " + " ".join(["layerpilot", *args]))
    t0 = time.monotonic()
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    took = time.monotonic() - t0
    out, err = run.stdout.splitlines(), run.stderr.splitlines()
    for line in out:
        print("      | " + line)
    for line in err:
        print("     !| " + line)
    say(f"exit {run.returncode} after {took:.1f} s")
    return run.returncode, out, err, took


def once(out: list[str], err: list[str]) -> list[str]:
    """Report lines that print twice (the same warning from the logger and from the event callback)."""
    texts = [line.removeprefix("link: ").strip() for line in out + err if line.strip()]
    texts = [t.split(" - ", 1)[-1] if " - " in t[:40] else t for t in texts]  # a logger's "time - name - "
    return sorted({t for t in texts if texts.count(t) > 1 and not t.startswith("t=")})


# ---------------------------------------------------------------------------------------------- steps

def step_ready(sitl: Sitl, ctx: dict) -> None:
    """Cold start (-w, default parameters): how long until layerpilot's wait_ready passes."""
    from layerpilot.link.config import LinkConfig
    from layerpilot.link.link import FlightLink

    sitl.start(wipe=True)
    events: list[tuple[float, str]] = []
    with FlightLink(LinkConfig(url=LINK_URL), on_event=lambda t: events.append((time.monotonic(), t))) as link:
        link.connect()
        t_hb = time.monotonic() - sitl.started
        say(f"first HEARTBEAT {t_hb:.1f} s after the process started (SITL boots when 5760 is connected)")
        t0 = time.monotonic()
        missing_at: list[tuple[float, list[str]]] = []
        stop = threading.Event()

        def sample() -> None:
            while not stop.wait(5.0):
                missing_at.append((time.monotonic() - t0, link.missing()))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        link.wait_ready()
        stop.set()
        ready = time.monotonic() - t0
        for t, missing in missing_at:
            print(f"      {t:5.1f} s: missing {missing}")
        for t, text in events:
            print(f"      link event at {t - t0:5.1f} s: {text}")
        ctx["ready_cold_s"] = ready
        say(f"ready {ready:.1f} s after the first HEARTBEAT ({ready + t_hb:.1f} s after the process started)")
        expect(ready < LinkConfig().ready_timeout_s,
               f"cold start ready in {ready:.1f} s, within the default ready_timeout_s {LinkConfig().ready_timeout_s:g}")


def step_cli(sitl: Sitl, ctx: dict) -> None:
    """`layerpilot link` takeoff / goto / land / rtl, and rtl and land on a disarmed vehicle."""
    w = ctx["watch"]
    runs = []

    def link(*args: str, timeout: float = 300.0):
        r = layerpilot("link", "--mavlink", LINK_URL, *args, timeout=timeout)
        runs.append(r)
        return r

    rc, *_ = link("takeoff", "20")
    expect(rc == 0, "takeoff 20: exit 0")
    soon(w, lambda: w.armed and w.mode == "GUIDED", "takeoff: ARMED in GUIDED")
    expect(abs(w.relative_alt() - 20.0) < 1.0, f"takeoff: relative_alt {w.relative_alt():.2f} m ~ 20 m")
    expect(abs(w.local()[2] + 20.0) < 1.0, f"takeoff: LOCAL_POSITION_NED.z {w.local()[2]:.2f} ~ -20 (origin at home)")

    rc, *_ = link("goto", "10", "5", "20")
    expect(rc == 0, "goto 10 5 20 (ENU): exit 0")
    time.sleep(3.0)
    n, e, d = w.local()
    err = math.dist((n, e, d), (5.0, 10.0, -20.0))
    expect(err < 1.0, f"goto: LOCAL_POSITION_NED ({n:.2f}, {e:.2f}, {d:.2f}) is {err:.2f} m from NED (5, 10, -20)")
    ctx["goto_error_m"] = err

    rc, *_ = link("rtl")
    expect(rc == 0, "rtl: exit 0")
    soon(w, lambda: not w.armed and math.hypot(*w.local()[:2]) < 2.0 and abs(w.local()[2]) < 0.5,
         "rtl: landed at home, disarmed")

    rc, _, err, _ = link("land")
    expect(rc != 0 and len(err) == 1 and "disarmed" in err[0], "land on a disarmed vehicle: exit non-zero, one error line")
    rc, _, err, _ = link("rtl")
    expect(rc != 0 and len(err) == 1 and "disarmed" in err[0], "rtl on a disarmed vehicle: exit non-zero, one error line")

    # (ArduCopter moves home to where it arms: landing away from home would move it; land here, at home)
    rc, *_ = link("takeoff", "10")
    expect(rc == 0, "takeoff 10: exit 0")
    soon(w, lambda: w.armed, "takeoff 10: ARMED")
    rc, *_ = link("land")
    expect(rc == 0, "land: exit 0")
    soon(w, lambda: not w.armed and math.hypot(*w.local()[:2]) < 2.0 and abs(w.local()[2]) < 0.5,
         "land: on the ground at home, disarmed")

    twice = sorted({t for _, out, err, _ in runs for t in once(out, err)})
    expect(not twice, f"each warning printed once{': twice ' + repr(twice) if twice else ''}")


def _plain_script() -> str:
    """The script of tests/test_sim_vehicle_ardupilot_script.py, unchanged."""
    spec = importlib.util.spec_from_file_location("plain_script", REPO / "tests" / "test_sim_vehicle_ardupilot_script.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.SCRIPT


def _run_script(port: int, timeout: float = 180.0) -> tuple[dict | None, str]:
    run = subprocess.run([sys.executable, "-c", _plain_script(), str(port)], capture_output=True, text=True,
                         timeout=timeout)
    if run.returncode != 0:
        return None, (run.stderr.strip().splitlines() or ["exit %d" % run.returncode])[-1]
    return json.loads(run.stdout.strip().splitlines()[-1]), ""


def _simulated() -> dict:
    """The same script against layerpilot's simulated ArduCopter (as the test flies it)."""
    from layerpilot.geodesy import LocalFrame
    from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
    from layerpilot.sim.vehicle import Multicopter

    ground = -5.7
    endpoint = MavlinkVehicle(Multicopter(position=(0.0, 0.0, ground), ground_z=ground), "tcp:127.0.0.1:0",
                              EndpointConfig(origin=LocalFrame(-35.363261, 149.165230, 584.0 - ground)))
    with endpoint.start(speed=5.0):
        seen, why = _run_script(endpoint.addresses[0][1])
    if seen is None:
        raise Mismatch(f"the plain script against the simulated vehicle failed: {why}")
    return seen


FIELDS = {"LOCAL_POSITION_NED": ("x", "y", "z"),
          "GLOBAL_POSITION_INT": ("lat", "lon", "alt", "relative_alt"),
          "HOME_POSITION": ("latitude", "longitude", "altitude", "x", "y", "z", "q"),
          "GPS_GLOBAL_ORIGIN": ("latitude", "longitude", "altitude"),
          "EKF_STATUS_REPORT": ("flags",)}


def step_script(sitl: Sitl, ctx: dict) -> None:
    """The plain ArduCopter script, real and simulated side by side; then home with `link rtl`."""
    w = ctx["watch"]
    real, why = _run_script(5760)
    expect(real is not None, f"the plain ArduCopter script flies the real SITL{': ' + why if why else ''}")
    sim = _simulated()
    print(f"      {'message.field':<34}{'real ArduCopter':>32}{'layerpilot sim':>32}")
    for where in ("ground", "there"):
        print(f"      -- {where} --")
        for kind, fields in FIELDS.items():
            for f in fields:
                print(f"      {kind + '.' + f:<34}{real[where][kind][f]!s:>32}{sim[where][kind][f]!s:>32}")
    for name, seen in (("real", real), ("sim", sim)):
        g, t = seen["ground"], seen["there"]
        home = g["HOME_POSITION"]
        expect(math.dist([g["LOCAL_POSITION_NED"][k] for k in "xyz"], (0, 0, 0)) < 0.3,
               f"{name}: LOCAL_POSITION_NED ~ (0, 0, 0) on the ground at home")
        expect(abs(g["GLOBAL_POSITION_INT"]["relative_alt"]) < 300, f"{name}: relative_alt ~ 0 on the ground")
        expect(abs(g["GLOBAL_POSITION_INT"]["alt"] - home["altitude"]) < 300,
               f"{name}: GLOBAL_POSITION_INT.alt ~ HOME_POSITION.altitude on the ground")
        expect(math.dist([home[k] for k in "xyz"], (0, 0, 0)) < 0.5, f"{name}: HOME_POSITION x, y, z ~ 0 (home at the origin)")
        o = g["GPS_GLOBAL_ORIGIN"]
        expect(abs(o["latitude"] - home["latitude"]) < 20 and abs(o["longitude"] - home["longitude"]) < 20
               and abs(o["altitude"] - home["altitude"]) < 1000,
               f"{name}: GPS_GLOBAL_ORIGIN at home (d_alt {o['altitude'] - home['altitude']} mm)")
        expect(bool(g["EKF_STATUS_REPORT"]["flags"] & mav.EKF_POS_HORIZ_ABS), f"{name}: EKF flags have POS_HORIZ_ABS")
        off = math.dist([t["LOCAL_POSITION_NED"][k] for k in "xyz"], (20, 10, -30))
        expect(off < 0.3, f"{name}: LOCAL_POSITION_NED {off:.2f} m from (20, 10, -30) at the target "
                          "(the script waited for 0.05 m; a real copter then drifts by centimetres)")
        expect(abs(t["GLOBAL_POSITION_INT"]["relative_alt"] - 30000) < 150
               and abs(t["GLOBAL_POSITION_INT"]["alt"] - home["altitude"] - 30000) < 300,
               f"{name}: 30 m above home in GLOBAL_POSITION_INT (relative_alt and alt)")
    ctx["script"] = {"real": real, "sim": sim}
    rc, *_ = layerpilot("link", "--mavlink", LINK_URL, "rtl")
    expect(rc == 0, "`link rtl` from the script's target: exit 0")
    soon(w, lambda: not w.armed and math.hypot(*w.local()[:2]) < 2.0, "back home and disarmed")


def _mission(sitl: Sitl, ctx: dict, name: str, end: str, mission: Path | str = "sitl-camera",
             cwd: Path | None = None, resume: bool = False) -> str:
    """`up --mission sitl-camera` (or ``mission``), ended by --duration 60 (``end`` = "duration"), by a
    signal 30 s after the takeoff ("SIGINT"), or by the pilot's battery return ("battery": SIGINT once
    the vehicle is home). Returns up's output and its nodes' logs."""
    w = ctx["watch"]
    if end != "battery" and w.last["SYS_STATUS"].battery_remaining < 80:  # else the pilot turns home for it
        swap_battery(sitl, w)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    logs = Path(tempfile.mkdtemp(prefix=f"sitl-{name}-", dir=sitl.workdir))
    args = ["up", "--mission", str(mission), "--endpoint", f"tcp/127.0.0.1:{port}", "--log-dir", str(logs),
            "--status-every", "10"] + (["--resume"] if resume else []) + (["--duration", "60"] if end == "duration" else [])
    cmd = [str(Path(sys.executable).with_name("layerpilot")), *args]
    say("$ layerpilot " + " ".join(args))
    t0 = time.monotonic()
    up = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=cwd or logs)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(up.stdout.readline, "")), daemon=True)
    reader.start()
    try:
        took = w.wait(lambda: w.armed and w.relative_alt() > 28.0, 180.0, f"{name}: takeoff to 30 m")
        say(f"{name}: ARMED and 30 m up {took:.1f} s after `up` started ({w.state()}, "
            f"battery {w.last['SYS_STATUS'].battery_remaining} %)")
        if end == "battery":
            turned = w.wait(lambda: w.mode == "RTL", 300.0, f"{name}: RTL for the battery")
            say(f"{name}: RTL {turned:.1f} s after reaching 30 m, battery {w.last['SYS_STATUS'].battery_remaining} %"
                f" ({w.state()})")
            w.wait(lambda: not w.armed, 240.0, f"{name}: home and disarmed")
            say(f"{name}: disarmed with {w.last['SYS_STATUS'].battery_remaining} % ({w.state()})")
            ctx[name + "_battery"] = {"turned_after_s": turned, "landed_with_pct":
                                      w.last["SYS_STATUS"].battery_remaining}
        if end in ("SIGINT", "battery"):
            if end == "SIGINT":
                time.sleep(30.0)
            say(f"{name}: SIGINT (Ctrl-C) to `up` (pid {up.pid}) while {w.state()}")
            up.send_signal(signal.SIGINT)
        rc = up.wait(timeout=180.0)
    finally:
        if up.poll() is None:
            up.kill()
            up.wait()
    reader.join(timeout=5.0)
    for line in lines:
        print("      | " + line.rstrip())
    t_exit = time.monotonic() - t0
    say(f"{name}: `up` exited {rc} after {t_exit:.1f} s; modes seen {w.seen_modes[-6:]}")
    text = "\n".join(lines) + "".join(p.read_text(errors="replace") for p in logs.glob("*.log"))
    if end == "battery":
        expect("returning home for the battery" in text, f"{name}: the link node says it returns for the battery")
    else:
        expect("RTL acknowledged" in text, f"{name}: the link says RTL acknowledged")
        soon(w, lambda: w.mode in ("RTL", "LAND") or not w.armed, f"{name}: the vehicle is in RTL after `up` ended")
    t_home = w.wait(lambda: not w.armed, 240.0, f"{name}: home and disarmed")
    n, e, d = w.local()
    say(f"{name}: disarmed {t_home:.1f} s after `up` exited, at NED ({n:.2f}, {e:.2f}, {d:.2f})")
    expect(math.hypot(n, e) < 2.0 and abs(d) < 0.5, f"{name}: landed at home ({w.state()})")
    ctx[name] = {"exit": rc, "up_s": t_exit, "home_after_s": t_home}
    return text


def step_up(sitl: Sitl, ctx: dict) -> None:
    _mission(sitl, ctx, "up", "duration")


def step_ctrlc(sitl: Sitl, ctx: dict) -> None:
    _mission(sitl, ctx, "ctrlc", "SIGINT")


def step_reboot(sitl: Sitl, ctx: dict) -> None:
    """A reboot on the ground (the command), then one in flight (kill and restart) under `link goto`."""
    from layerpilot.link.config import LinkConfig
    from layerpilot.link.link import FlightLink

    w = ctx["watch"]
    boots, before = w.boots, w.uptimes[-1][1]
    t0 = time.monotonic()
    w.send_command(mav.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)
    say(f"MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN (1) sent on the ground (uptime {before:.1f} s)")
    # the rebooted SITL waits for a client on 5760 again: a link connects, as layerpilot's would
    with FlightLink(LinkConfig(url=LINK_URL)) as link:
        link.connect(timeout=30.0)
        w.wait(lambda: w.boots > boots and w.uptimes[-1][0] > t0 + 1.0, 60.0, "the SITL back after the reboot")
        back = time.monotonic() - t0
        after = w.uptimes[-1][1]
        link.wait_ready()
        ready = time.monotonic() - t0
    say(f"HEARTBEAT back {back:.1f} s after the command; ready again {ready:.1f} s after it; time_boot_ms "
        f"{before:.1f} s before the reboot, {after:.1f} s after it")
    ctx["reboot_ready_s"], ctx["reboot_uptime_s"] = ready, (before, after)

    rc, *_ = layerpilot("link", "--mavlink", LINK_URL, "takeoff", "20")
    expect(rc == 0, "takeoff 20 for the in-flight restart")
    cmd = [str(Path(sys.executable).with_name("layerpilot")), "link", "--mavlink", LINK_URL, "--timeout", "120",
           "goto", "60", "0", "20"]
    say("$ layerpilot " + " ".join(cmd[1:]) + "   (SITL killed and restarted while it flies)")
    goto = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(6.0)
        sitl.kill()
        time.sleep(2.0)
        sitl.start(wipe=False)
        t0 = time.monotonic()
        out, err = goto.communicate(timeout=150.0)
    finally:
        if goto.poll() is None:
            goto.kill()
            goto.wait()
    took = time.monotonic() - t0
    for line in out.splitlines():
        print("      | " + line)
    for line in err.splitlines():
        print("     !| " + line)
    say(f"goto exited {goto.returncode} {took:.1f} s after the restart")
    ctx["goto_after_restart_s"] = took
    expect(goto.returncode != 0, "goto across a restart: exit non-zero")
    expect("reboot" in (out + err).lower(), "goto says the autopilot rebooted")
    expect(took < 30.0, f"goto ends promptly after the restart ({took:.1f} s)")
    w.wait(lambda: w.alive() and not w.armed, 60.0, "the restarted SITL is heard, disarmed")


def swap_battery(sitl: Sitl, w: Watch) -> None:
    """Kill and restart the SITL (parameters kept): its simulated battery starts full at every boot."""
    boots = w.boots
    sitl.kill()
    sitl.start(wipe=False)
    sitl.boot()
    took = w.wait(lambda: w.boots > boots and w.last["EKF_STATUS_REPORT"].flags & mav.EKF_POS_HORIZ_ABS
                  and w.last["SYS_STATUS"].battery_remaining >= 99, 120.0, "a full battery after the restart")
    say(f"battery swapped (SITL restarted): full, EKF position {took:.1f} s after the boot")


def step_battery(sitl: Sitl, ctx: dict) -> None:
    """A battery return (decide.battery_reserve 0.85 on SITL's simulated battery), a swap, `up --resume`."""
    w = ctx["watch"]
    swap_battery(sitl, w)
    text = (REPO / "config" / "missions" / "sitl-camera.toml").read_text()
    # the reserve the pilot lands with: high, so that it turns home within a minute of flight
    mission = sitl.workdir / "sitl-battery.toml"
    mission.write_text(text.replace('behavior = "balanced"', 'behavior = "balanced"\nbattery_reserve = 0.85'))
    run = sitl.workdir / "battery-run"
    run.mkdir(exist_ok=True)
    first = _mission(sitl, ctx, "battery", "battery", mission=mission, cwd=run)
    expect("battery" in first, "battery: the pilot turned home for the battery (return: battery)")
    swap_battery(sitl, w)
    second = _mission(sitl, ctx, "resume", "duration", mission=mission, cwd=run, resume=True)
    expect("resume" in second, "resume: the decide node continued the saved survey")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("binary", type=Path, help="build/sitl/bin/arducopter")
    ap.add_argument("--defaults", type=Path,
                    help="parameter file (default: Tools/autotest/default_params/copter.parm of its tree)")
    ap.add_argument("--speedup", type=float, default=1.0, help="SITL's --speedup (1 = real time, the default)")
    ap.add_argument("--only", help=f"comma-separated steps of {', '.join(STEPS)} (default: all, in that order)")
    ap.add_argument("--workdir", type=Path, help="where the SITL keeps eeprom.bin and logs (default: a temp dir)")
    args = ap.parse_args(argv)
    binary = args.binary.resolve()
    defaults = args.defaults or binary.parents[3] / "Tools/autotest/default_params/copter.parm"
    steps = STEPS if not args.only else tuple(args.only.split(","))
    for problem in ([f"{binary} is not an executable"] if not os.access(binary, os.X_OK) else []) + \
            ([f"no parameter file {defaults}"] if not defaults.is_file() else []) + \
            [f"unknown step {s!r} (steps: {', '.join(STEPS)})" for s in steps if s not in STEPS]:
        ap.error(problem)
    if subprocess.run(["ss", "-Hltn", "sport = :5760"], capture_output=True, text=True).stdout.strip():
        ap.error("something already listens on port 5760 (another SITL?)")
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="sitl-check-"))
    workdir.mkdir(parents=True, exist_ok=True)
    sitl = Sitl(binary, defaults, workdir, args.speedup)
    ctx: dict = {}
    results: list[tuple[str, str]] = []
    try:
        if "ready" not in steps:
            sitl.start(wipe=True)
            sitl.boot()
        for name in STEPS:
            if name not in steps:
                continue
            if name != "ready" and "watch" not in ctx:
                ctx["watch"] = Watch()
                ctx["watch"].wait(lambda: "EKF_STATUS_REPORT" in ctx["watch"].last and not ctx["watch"].armed
                                  and ctx["watch"].last["EKF_STATUS_REPORT"].flags & mav.EKF_POS_HORIZ_ABS,
                                  180.0, "the SITL has a position")
            say(f"=== {name}: {globals()['step_' + name].__doc__.splitlines()[0] if globals()['step_' + name].__doc__ else ''}")
            try:
                globals()["step_" + name](sitl, ctx)
                results.append((name, "ok"))
            except (Mismatch, subprocess.TimeoutExpired, KeyError, LinkError) as exc:
                results.append((name, f"FAIL: {exc}"))
                say(f"step {name} failed: {exc}")
                if "watch" in ctx and ctx["watch"].armed:  # leave the vehicle on the ground for the next step
                    ctx["watch"].send_command(mav.MAV_CMD_NAV_RETURN_TO_LAUNCH)
                    ctx["watch"].wait(lambda: not ctx["watch"].armed, 240.0, "home after a failed step")
    finally:
        if "watch" in ctx:
            ctx["watch"].close()
        sitl.kill()
    print()
    for name, result in results:
        print(f"{name:<8} {result}")
    summary = {k: (round(v, 2) if isinstance(v, float) else v) for k, v in ctx.items() if k not in ("watch", "script")}
    print(json.dumps({"sitl": str(binary), "results": dict(results), "measured": summary}))
    return 0 if all(r == "ok" for _, r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
