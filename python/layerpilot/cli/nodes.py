"""Node processes: `layerpilot map-server|decide`, `layerpilot router`, `layerpilot up`, and
``add_node_command``, how every `layerpilot ROLE` runs its bus node in this process.

`sim`, `link` and `depth` (cli.sim, cli.link, cli.depth) add their node commands here too,
with actions of their own (`layerpilot sim preview`, `layerpilot link takeoff 20`,
`layerpilot depth preview`); without an action they run their bus node. Every node reads the mission file (``--config``: a path or a name in
config/missions/), prints one JSON line when ready and a JSON status line every
``--status-every`` seconds, and on SIGTERM/SIGINT finishes its current message, prints a
last status line and exits 0.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from dataclasses import dataclass, field
from typing import Any, Callable


def register(commands: argparse._SubParsersAction) -> None:
    p = add_node_command(commands, "map-server", _map_server,
                         "the map daemon: clouds in, layer sets and map queries out (one for all vehicles)")
    p.add_argument("--snapshot", help="snapshot .ot path (reloaded at start); '' for none")
    add_node_command(commands, "decide", _decide, "layer sets + pose in, decisions and waypoints out")

    p = commands.add_parser("router", help="a Zenoh router for several machines (nodes then use mode = client)")
    p.add_argument("--config", help="mission file or name (for its [bus] table)")
    p.add_argument("--endpoint", help="listen endpoint (default tcp/127.0.0.1:7447)")
    p.set_defaults(func=_router)

    p = commands.add_parser("up", help="run a mission: every node as a process, status lines, restarts, clean stop")
    p.add_argument("--mission", help="mission file or name in config/missions/ (default: default)")
    p.add_argument("--endpoint", help="Zenoh endpoint the nodes meet at (default: the mission's)")
    p.add_argument("--status-every", type=float, default=2.0, help="seconds between status blocks")
    p.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
    p.add_argument("--log-dir", default="runs/logs", help="each node's log (stderr) goes to <log-dir>/<node>.log")
    p.set_defaults(func=_up)


def add_node_command(commands: argparse._SubParsersAction, role: str, build: Builder, help: str,
                     description: str | None = None) -> argparse.ArgumentParser:
    """`layerpilot ROLE` running the role's bus node, started by ``build(args, mission, tables, vehicle,
    session)``; the caller adds the role's own options."""
    p = commands.add_parser(role, help=help, description=description or help)
    p.add_argument("--config", help="mission file or name in config/missions/ (default: default)")
    p.add_argument("--vehicle", default=None, help="vehicle name (default: the mission's first)")
    p.add_argument("--endpoint", help="Zenoh endpoint (default: the mission's, tcp/127.0.0.1:7447)")
    p.add_argument("--status-every", type=float, default=2.0, help="seconds between JSON status lines")
    p.set_defaults(func=_run_node, role=role, build=build)
    return p


@dataclass
class Running:
    """A started node: its status counters, its stop(), what it tells when ready, and its blocking
    run(stop) (by default: wait for the stop, for nodes that work on their own threads)."""

    status: Callable[[], dict]
    stop: Callable[[], None] = lambda: None
    info: dict[str, Any] = field(default_factory=dict)
    run: Callable[[threading.Event], None] | None = None


Builder = Callable[..., Running]

_SAY_LOCK = threading.Lock()


def _say(**fields: Any) -> None:
    """One JSON line, written whole: the status ticker and the main thread must not interleave."""
    with _SAY_LOCK:
        sys.stdout.write(json.dumps(fields) + "\n")
        sys.stdout.flush()


def _run_node(args: argparse.Namespace) -> int:
    from layerpilot.bus.session import open_session
    from layerpilot.nodes.mission import load_mission
    from layerpilot.nodes.runner import bus_config, stop_event, wait_for_stop

    mission, tables = load_mission(args.config)
    vehicle = args.vehicle or mission.vehicles[0]
    if vehicle not in mission.vehicles:
        raise ValueError(f"--vehicle {vehicle!r}: the mission's vehicles are {mission.vehicles}")
    stop = stop_event()
    session = open_session(bus_config(tables, args.endpoint))
    try:
        node = args.build(args, mission, tables, vehicle, session)
        _say(node=args.role, vehicle=vehicle, status="ready", **node.info)
        ticker = threading.Thread(target=_status_loop, args=(stop, args, vehicle, node.status), daemon=True)
        ticker.start()
        (node.run or wait_for_stop)(stop)
        stop.set()  # also when run() ended by itself (sim --duration): the ticker stops before the last line
        ticker.join()
        node.stop()
        _say(node=args.role, vehicle=vehicle, status="stopped", **node.status())
    finally:
        session.close()
    return 0


def _status_loop(stop: threading.Event, args: argparse.Namespace, vehicle: str, status: Callable[[], dict]) -> None:
    while not stop.wait(args.status_every):
        _say(node=args.role, vehicle=vehicle, **status())


def _map_server(args, mission, tables, vehicle, session) -> Running:
    from layerpilot.config import from_dict
    from layerpilot.nodes.map_server import MapServer, MapServerConfig

    data = dict(tables.get("map_server", {}))
    if args.snapshot is not None:
        data["snapshot"] = args.snapshot
    node = MapServer(session, from_dict(MapServerConfig, data, "map_server"))
    node.start()
    c = node.counters
    return Running(lambda: {"received": c.clouds_received, "inserted": c.clouds_inserted,
                            "dropped": c.clouds_dropped, "rejected": node.rejects.total,
                            "layer_sets": c.layer_sets_published, "queries": c.queries_answered,
                            "snapshots": c.snapshots_written, "leaves": node.map.stats()["leaves"]},
                   node.stop, {"snapshot": node.cfg.snapshot})


def _decide(args, mission, tables, vehicle, session) -> Running:
    from layerpilot.config import from_dict
    from layerpilot.nodes.decide import DecideConfig, DecideNode

    node = DecideNode(session, vehicle, from_dict(DecideConfig, tables.get("decide", {}), "decide"))
    node.start()
    return Running(lambda: {"decisions": node.seq, "reached": node.reached,
                            "distance": round(node.distance_flown, 1), "rejected": node.rejects.total},
                   node.stop, {"behavior": node.cfg.behavior})


def _router(args: argparse.Namespace) -> int:
    from layerpilot.bus.session import open_session
    from layerpilot.nodes.runner import bus_config, load_tables, stop_event, wait_for_stop

    stop = stop_event()
    tables = load_tables(args.config) if args.config else {}
    session = open_session(bus_config(tables, args.endpoint, mode="router"))
    _say(node="router", status="ready", zid=str(session.zid()))
    wait_for_stop(stop)
    session.close()
    return 0


def _up(args: argparse.Namespace) -> int:
    from layerpilot.nodes.up import up

    return up(args.mission, endpoint=args.endpoint, status_every=args.status_every, duration=args.duration,
              log_dir=args.log_dir)

