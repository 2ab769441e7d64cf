"""Node processes: `layerpilot node map-server|sim|link|depth|decide` (also `layerpilot map-server`
and `layerpilot decide`), `layerpilot router`, `layerpilot up`; `layerpilot bench bus`.

`layerpilot sim|link|depth` are the simulator's, link's and depth's own commands (standalone
tools), so their bus processes live under `layerpilot node`.

Every node reads the mission file (``--config``: a path or a name in config/missions/),
prints one JSON line when ready and a JSON status line every ``--status-every`` seconds,
and on SIGTERM/SIGINT finishes its current message, prints a last status line and exits 0.
"""

from __future__ import annotations

import argparse
import json
import threading
from typing import Any, Callable

ROLES = ("map-server", "sim", "link", "depth", "decide")


def register(commands: argparse._SubParsersAction, benches: argparse._SubParsersAction) -> None:
    helps = {
        "map-server": "the map daemon: clouds in, layer sets and map queries out (one for all vehicles)",
        "sim": "simulated vehicle: renders camera frames onto the bus, serves MAVLink",
        "link": "MAVLink flight link: waypoints from the bus to the autopilot, pose back",
        "depth": "camera frames in, point clouds out",
        "decide": "layer sets + pose in, decisions and waypoints out",
    }
    node = commands.add_parser("node", help="run one bus node of a mission (what `layerpilot up` starts)")
    roles = node.add_subparsers(dest="role", required=True, metavar="ROLE")
    for role in ROLES:
        _node_parser(roles, role, helps[role])
    for role in ("map-server", "decide"):  # the two roles without a standalone command of the same name
        _node_parser(commands, role, helps[role])

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

    b = benches.add_parser("bus", help="map server on loopback: layer-query round trip, cloud throughput")
    b.add_argument("--seconds", type=float, default=5.0, help="seconds of clouds to send")
    b.add_argument("--rate", type=float, default=10.0, help="clouds per second offered")
    b.set_defaults(func=_bench_bus)


def _node_parser(parent: argparse._SubParsersAction, role: str, help: str) -> None:
    p = parent.add_parser(role, help=help)
    _node_args(p)
    if role in ("sim", "link"):
        p.add_argument("--mavlink", help="MAVLink URL (default: the mission's for this vehicle)")
    if role == "map-server":
        p.add_argument("--snapshot", help="snapshot .ot path (reloaded at start); '' for none")
    p.set_defaults(func=_run_node, role=role)


def _node_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="mission file or name in config/missions/ (default: default)")
    p.add_argument("--vehicle", default=None, help="vehicle name (default: the mission's first)")
    p.add_argument("--endpoint", help="Zenoh endpoint (default: the mission's, tcp/127.0.0.1:7447)")
    p.add_argument("--status-every", type=float, default=2.0, help="seconds between JSON status lines")


def _say(**fields: Any) -> None:
    print(json.dumps(fields), flush=True)


def _run_node(args: argparse.Namespace) -> int:
    from layerpilot.bus.session import open_session
    from layerpilot.config import from_dict
    from layerpilot.nodes.mission import load_mission
    from layerpilot.nodes.runner import bus_config, stop_event

    mission, tables = load_mission(args.config)
    vehicle = args.vehicle or mission.vehicles[0]
    stop = stop_event()
    session = open_session(bus_config(tables, args.endpoint))
    try:
        node, status, run = _build(args, mission, tables, vehicle, session, from_dict)
        _say(node=args.role, vehicle=vehicle, status="ready")
        ticker = threading.Thread(target=_status_loop, args=(stop, args, vehicle, status), daemon=True)
        ticker.start()
        run(stop)
        node.stop() if hasattr(node, "stop") else None
        _say(node=args.role, vehicle=vehicle, status="stopped", **status())
    finally:
        session.close()
    return 0


def _status_loop(stop: threading.Event, args: argparse.Namespace, vehicle: str, status: Callable[[], dict]) -> None:
    while not stop.wait(args.status_every):
        _say(node=args.role, vehicle=vehicle, **status())


def _build(args, mission, tables, vehicle, session, from_dict):
    """(node, status() -> dict, run(stop)) for the role; run blocks until stop is set."""
    wait = lambda stop: stop.wait()  # noqa: E731 - nodes that work on their own threads
    if args.role == "map-server":
        from layerpilot.nodes.map_server import MapServer, MapServerConfig

        data = dict(tables.get("map_server", {}))
        if args.snapshot is not None:
            data["snapshot"] = args.snapshot
        node = MapServer(session, from_dict(MapServerConfig, data, "map_server"))
        node.start()
        c = node.counters
        return node, lambda: {"received": c.clouds_received, "inserted": c.clouds_inserted,
                              "dropped": c.clouds_dropped, "rejected": node.rejects.total,
                              "layer_sets": c.layer_sets_published, "queries": c.queries_answered,
                              "snapshots": c.snapshots_written, "leaves": node.map.stats()["leaves"]}, wait
    if args.role == "depth":
        from layerpilot.nodes.depth import DepthNode, DepthNodeConfig

        node = DepthNode(session, vehicle, from_dict(DepthNodeConfig, tables.get("depth", {}), "depth"))
        node.start()
        q = node.queue
        return node, lambda: {"frames": q.received, "dropped": q.dropped, "clouds": node.clouds,
                              "rejected": node.rejects.total}, wait
    if args.role == "decide":
        from layerpilot.nodes.decide import DecideConfig, DecideNode

        node = DecideNode(session, vehicle, from_dict(DecideConfig, tables.get("decide", {}), "decide"))
        node.start()
        return node, lambda: {"decisions": node.seq, "reached": node.reached,
                              "distance": round(node.distance_flown, 1), "rejected": node.rejects.total}, wait
    if args.role == "link":
        from layerpilot.nodes.link import LinkNodeConfig, LinkNode

        data = dict(tables.get("link", {}))
        if args.mavlink or not mission.camera_only:  # camera-only: the real autopilot's URL from [link.link]
            data["link"] = {**data.get("link", {}), "url": args.mavlink or mission.mavlink_url(vehicle)}
        node = LinkNode(session, vehicle, from_dict(LinkNodeConfig, data, "link"))
        node.start()
        return node, lambda: {"waypoints": node.waypoints, "rejected": node.rejects.total,
                              "telemetry": node.link.telemetry().line()}, wait
    from layerpilot.nodes.sim import CameraOnlyNode, SimNode
    from layerpilot.sim.simulator import SimConfig

    data = dict(tables.get("sim", {}))
    if mission.camera_only:
        node = CameraOnlyNode(session, vehicle, from_dict(SimConfig, data, "sim"))
        return node, lambda: {"frames": node.frames, "rejected": node.rejects.total}, node.run
    data["urls"] = [args.mavlink or mission.mavlink_url(vehicle)]
    node = SimNode(session, vehicle, from_dict(SimConfig, data, "sim"), speed=mission.speed)
    return node, lambda: {"frames": node.frames, "time": round(node.sim.time, 2)}, node.run


def _router(args: argparse.Namespace) -> int:
    from layerpilot.bus.session import open_session
    from layerpilot.nodes.runner import bus_config, load_tables, stop_event

    stop = stop_event()
    tables = load_tables(args.config) if args.config else {}
    session = open_session(bus_config(tables, args.endpoint, mode="router"))
    _say(node="router", status="ready", zid=str(session.zid()))
    stop.wait()
    session.close()
    return 0


def _up(args: argparse.Namespace) -> int:
    from layerpilot.nodes.up import up

    return up(args.mission, endpoint=args.endpoint, status_every=args.status_every, duration=args.duration,
              log_dir=args.log_dir)


def _bench_bus(args: argparse.Namespace) -> int:
    from layerpilot.nodes.bench import main

    return main(args.seconds, args.rate)
