"""Watch, record and replay: `layerpilot view`, `layerpilot record`, `layerpilot replay`."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from layerpilot.cli.nodes import add_ros2_record_flag


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("view", help="join a running mission on the bus and show it live in Rerun")
    _bus_options(p)
    p.add_argument("--vehicle", help="vehicle to follow (default: the mission's first)")
    p.add_argument("--web", action="store_true", help="serve the web viewer instead of the native one (the page on every "
                   "interface, Rerun 0.41 cannot bind it; the data server on 127.0.0.1 only)")
    p.add_argument("--web-port", type=int, default=9090, help="the web viewer page's port (default 9090)")
    p.add_argument("--grpc-port", type=int, default=9876, help="Rerun's data server port (default 9876)")
    p.add_argument("--color-by", choices=["color", "height", "age"], default="color",
                   help="occupied voxels coloured by their color, height or time since seen")
    p.add_argument("--save", help="also write the view to this .rrd file")
    p.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
    p.set_defaults(func=_view)

    p = commands.add_parser("record", help="write every message of a running mission's bus to an MCAP file")
    _bus_options(p)
    p.add_argument("out", help="the .mcap file to write")
    p.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
    add_ros2_record_flag(p)
    p.set_defaults(func=_record)

    p = commands.add_parser("replay", help="rebuild a recording's map, and what another behavior would have chosen")
    p.add_argument("recording", help="an .mcap file from `layerpilot record` or `up --record`")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--behavior", help="preset, .toml path or pattern asked at every layer tick")
    what.add_argument("--map-only", action="store_true", help="only rebuild the map from the recorded clouds")
    p.add_argument("--config", help="mission file or name (default: the one kept in the recording)")
    p.add_argument("--vehicle", help="vehicle whose flight is replayed (default: the mission's first)")
    p.add_argument("--out", help="output directory (default: beside the recording, <name>-replay)")
    p.set_defaults(func=_replay)


def _bus_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="mission file or name in config/missions/ (default: default)")
    p.add_argument("--endpoint", help="Zenoh endpoint of the mission (default: the mission's)")
    p.add_argument("--credentials", help="the operator's login (`layerpilot up` writes it into its secrets "
                                         "directory, e.g. runs/bus-secrets/operator.json); without it, an open peer")


def _session(args: argparse.Namespace):
    from layerpilot.bus.security import open_node_session
    from layerpilot.missionfile import load_mission
    from layerpilot.nodes.runner import bus_config

    mission = load_mission(args.config)
    return mission, open_node_session(bus_config(mission.bus, args.endpoint), args.credentials)


def _wait(duration: float | None) -> None:
    from layerpilot.nodes.runner import stop_event, wait_for_stop

    stop = stop_event()
    if duration is None:
        wait_for_stop(stop)
    else:
        end = time.monotonic() + duration
        while not stop.wait(0.2) and time.monotonic() < end:
            pass


def _view(args: argparse.Namespace) -> int:
    from layerpilot.eval.metrics import area_metrics
    from layerpilot.viz.live import LiveView
    from layerpilot.viz.scene import MissionScene
    from layerpilot.viz.stream import open_stream

    mission, session = _session(args)
    vehicle = args.vehicle or mission.vehicles[0]
    if vehicle not in mission.vehicles:
        raise ValueError(f"--vehicle {vehicle!r}: the mission's vehicles are {mission.vehicles}")
    try:
        stream = open_stream(f"live-{vehicle}", save=args.save, web_port=args.web_port if args.web else None,
                             grpc_port=args.grpc_port, spawn=not args.web)
    except (OSError, ValueError):  # a busy port, no display: one line from main, nothing left open
        session.close()
        raise
    view = LiveView(session, mission, MissionScene(stream.stream, args.color_by), vehicle,
                    metrics=lambda cl, aoi, now: area_metrics(cl, aoi, now).as_dict(),
                    warn=lambda line: print(f"layerpilot view: warning: {line}", file=sys.stderr, flush=True))
    view.start()
    print(json.dumps({"node": "view", "vehicle": vehicle, "status": "ready",
                      **({"url": stream.url} if stream.url else {})}), flush=True)
    try:
        _wait(args.duration)
    finally:
        view.stop()
        stream.close()
        session.close()
    print(json.dumps({"node": "view", "status": "stopped", "heard": dict(view.heard), "logged": dict(view.logged),
                      "rejected": view.rejects.total}), flush=True)
    return 0


def _record(args: argparse.Namespace) -> int:
    from layerpilot.bus.recording import Recorder
    from layerpilot.missionfile import resolve
    from layerpilot.ros2.recording import recording_options

    mission, session = _session(args)
    try:
        recorder = Recorder(session, args.out, resolve(args.config).read_text(),
                            **recording_options(args.ros2, mission.ros2))
    except OSError as exc:
        session.close()
        raise OSError(f"out: {exc}") from None
    print(json.dumps({"node": "record", "status": "ready", "out": args.out}), flush=True)
    try:
        _wait(args.duration)
    finally:
        summary = recorder.stop()
        session.close()
    print(json.dumps({"node": "record", "status": "stopped", **summary}), flush=True)
    if summary["error"]:
        print(f"layerpilot record: error: the recording is incomplete: {summary['error']}; "
              f"{summary['dropped']} messages dropped", file=sys.stderr)
        return 1
    return 0


def _replay(args: argparse.Namespace) -> int:
    from layerpilot.eval.replay import replay

    recording = Path(args.recording)
    out = Path(args.out) if args.out else recording.with_name(recording.stem + "-replay")
    result = replay(recording, out, mission=None if args.config is None else _load(args.config),
                    behavior=None if args.map_only else args.behavior, vehicle=args.vehicle)
    if result.damage:
        print(f"layerpilot replay: warning: {result.damage}", file=sys.stderr)
    if result.unknown_schemas:
        print(f"layerpilot replay: skipped messages of unknown schemas: {result.unknown_schemas}", file=sys.stderr)
    print(f"map: {result.map_path} ({result.clouds} clouds)")
    if not args.map_only:
        chosen = sum("waypoint" in d for d in result.decisions)
        print(f"{args.behavior}: {chosen} choices at {len(result.decisions)} layer ticks, "
              f"{len(result.flown)} flown decisions: {out / 'decisions.jsonl'}")
        print(f"picture: {result.pictures['comparison']}")
    return 0


def _load(config: str):
    from layerpilot.missionfile import load_mission

    return load_mission(config)
