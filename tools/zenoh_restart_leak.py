"""Minimal reproduction: does a Zenoh router (and a client of it) keep memory each time a peer is SIGKILLed?

Plain eclipse-zenoh, no layerpilot code: one router on 127.0.0.1, one "watcher" client that
subscribes to everything, and a "victim" client that declares a subscriber and a queryable and
puts 100 KB a second, as a layerpilot node does. The victim is started, left running for
``--alive`` seconds, killed with SIGKILL, and after ``--gap`` seconds started again. The
resident memory (VmRSS) of the router and of the watcher is printed after every kill.

    python tools/zenoh_restart_leak.py --kills 6 --gap 15

Run it with the eclipse-zenoh under test (``python -m pip install eclipse-zenoh==X`` in a scratch venv).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for pid {pid}")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def config(mode: str, endpoint: str, extra: list[str]):
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", f'"{mode}"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    for item in extra:  # KEY=JSON5, e.g. transport/shared_memory/enabled=false
        key, value = item.split("=", 1)
        conf.insert_json5(key, value)
    if mode == "router":
        conf.insert_json5("listen/endpoints", f'["{endpoint}"]')
    else:
        conf.insert_json5("connect/endpoints", f'["{endpoint}"]')
    return conf


def serve(role: str, endpoint: str, extra: list[str]) -> None:
    """One process of the experiment; runs until killed."""
    import zenoh

    session = zenoh.open(config("router" if role == "router" else "client", endpoint, extra))
    decls = []
    if role == "watcher":
        decls.append(session.declare_subscriber("leak/**", lambda sample: None))
    elif role == "victim":
        decls.append(session.declare_subscriber("leak/in", lambda sample: None))
        decls.append(session.declare_queryable("leak/query", lambda query: query.reply("leak/query", b"ok")))
    print("ready", flush=True)
    payload = bytes(100_000)
    while True:
        if role == "victim":
            session.put("leak/out", payload)
        time.sleep(1.0)


def start(role: str, endpoint: str, extra: list[str]) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, __file__, "--role", role, "--endpoint", endpoint,
                          *(a for item in extra for a in ("--set", item))], stdout=subprocess.PIPE, text=True)
    if p.stdout.readline().strip() != "ready":
        raise RuntimeError(f"{role} did not start")
    return p


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--role", choices=("router", "watcher", "victim"), help=argparse.SUPPRESS)
    ap.add_argument("--endpoint", default=None)
    ap.add_argument("--kills", type=int, default=6)
    ap.add_argument("--alive", type=float, default=5.0, help="s the victim runs before each SIGKILL")
    ap.add_argument("--gap", type=float, default=15.0, help="s between a SIGKILL and the next start")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=JSON5",
                    help="a Zenoh configuration key for every process, e.g. transport/shared_memory/enabled=false")
    args = ap.parse_args()
    if args.role:
        serve(args.role, args.endpoint, args.set)
        return
    endpoint = args.endpoint or f"tcp/127.0.0.1:{free_port()}"
    version = importlib.metadata.version("eclipse-zenoh")
    router = start("router", endpoint, args.set)
    watcher = start("watcher", endpoint, args.set)
    procs = [router, watcher]
    try:
        time.sleep(args.gap)
        base = rss_mb(router.pid), rss_mb(watcher.pid)
        print(f"eclipse-zenoh {version} {' '.join(args.set)}; baseline RSS: router {base[0]:.1f} MB, "
              f"watcher {base[1]:.1f} MB", flush=True)
        for i in range(1, args.kills + 1):
            victim = start("victim", endpoint, args.set)
            time.sleep(args.alive)
            os.kill(victim.pid, signal.SIGKILL)
            victim.wait()
            time.sleep(args.gap)
            r, w = rss_mb(router.pid), rss_mb(watcher.pid)
            print(f"after kill {i}: router {r:.1f} MB ({r - base[0]:+.1f}), watcher {w:.1f} MB ({w - base[1]:+.1f})",
                  flush=True)
    finally:
        for p in procs:
            p.terminate()
            p.wait()


if __name__ == "__main__":
    main()
