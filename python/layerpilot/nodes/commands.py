"""Node processes: `layerpilot map-server`, `decide`, `router`; `layerpilot bench bus`."""

from __future__ import annotations

import argparse
import json


def register(commands: argparse._SubParsersAction, benches: argparse._SubParsersAction) -> None:
    p = commands.add_parser("map-server", help="the map daemon: clouds in, layer sets and map queries out")
    _bus_args(p)
    p.add_argument("--snapshot", help="snapshot .ot path (reloaded at start); '' for none")
    p.add_argument("--snapshot-period", type=float, help="seconds between snapshots (default 30)")
    p.add_argument("--layers-rate", type=float, help="layer sets per second (default 1)")
    p.add_argument("--resolution", type=float, help="voxel size in metres")
    p.add_argument("--status-every", type=float, default=5.0, help="seconds between JSON status lines on stdout")
    p.set_defaults(func=_map_server)

    p = commands.add_parser("decide", help="the decision node of one vehicle: layers + pose in, waypoints out")
    _bus_args(p)
    p.add_argument("--vehicle", default="uav1", help="vehicle name (key chunk)")
    p.add_argument("--behavior", help="behavior preset or .toml (default: the mission's, else balanced)")
    p.set_defaults(func=_decide)

    b = benches.add_parser("bus", help="map server on loopback: layer-query round trip, cloud throughput")
    b.add_argument("--seconds", type=float, default=5.0, help="seconds of clouds to send")
    b.add_argument("--rate", type=float, default=10.0, help="clouds per second offered")
    b.set_defaults(func=lambda a: __import__("layerpilot.nodes.bench", fromlist=["main"]).main(a.seconds, a.rate))

    p = commands.add_parser("router", help="a Zenoh router for several machines (nodes then run with mode=client)")
    _bus_args(p)
    p.set_defaults(func=_router)


def _bus_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="mission TOML ([bus] and the node's own table)")
    p.add_argument("--endpoint", help="Zenoh endpoint (default tcp/127.0.0.1:7447)")


def _map_server(args: argparse.Namespace) -> int:
    from layerpilot.bus.session import open_session
    from layerpilot.nodes.map_server import MapServer, MapServerConfig
    from layerpilot.nodes.runner import bus_config, load_tables, stop_event, table

    tables = load_tables(args.config)
    cfg = table(MapServerConfig, tables, "map_server",
                {"snapshot": args.snapshot, "snapshot_period": args.snapshot_period,
                 "layers_rate": args.layers_rate, "resolution": args.resolution})
    stop = stop_event()
    session = open_session(bus_config(tables, args.endpoint))
    server = MapServer(session, cfg)
    server.start()
    print(json.dumps({"node": "map-server", "status": "ready", "leaves": server.map.stats()["leaves"]}), flush=True)
    while not stop.wait(args.status_every):
        _status(server)
    server.stop()
    _status(server)
    session.close()
    return 0


def _decide(args: argparse.Namespace) -> int:
    from layerpilot.bus.session import open_session
    from layerpilot.nodes.decide import DecideConfig, DecideNode
    from layerpilot.nodes.runner import bus_config, load_tables, stop_event, table

    tables = load_tables(args.config)
    cfg = table(DecideConfig, tables, "decide", {"behavior": args.behavior})
    stop = stop_event()
    session = open_session(bus_config(tables, args.endpoint))
    node = DecideNode(session, args.vehicle, cfg)
    node.start()
    print(json.dumps({"node": "decide", "vehicle": args.vehicle, "status": "ready"}), flush=True)
    stop.wait()
    node.stop()
    print(json.dumps({"node": "decide", "vehicle": args.vehicle, "decisions": node.seq, "reached": node.reached,
                      "rejected": node.rejects.total}), flush=True)
    session.close()
    return 0


def _status(server) -> None:
    c = server.counters
    print(json.dumps({"node": "map-server", "received": c.clouds_received, "inserted": c.clouds_inserted,
                      "dropped": c.clouds_dropped, "rejected": server.rejects.total,
                      "layer_sets": c.layer_sets_published, "queries": c.queries_answered,
                      "snapshots": c.snapshots_written}), flush=True)


def _router(args: argparse.Namespace) -> int:
    from layerpilot.bus.session import open_session
    from layerpilot.nodes.runner import bus_config, load_tables, stop_event

    stop = stop_event()
    session = open_session(bus_config(load_tables(args.config), args.endpoint, mode="router"))
    print(json.dumps({"node": "router", "status": "ready", "zid": str(session.zid())}), flush=True)
    stop.wait()
    session.close()
    return 0
