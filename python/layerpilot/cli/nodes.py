"""Node processes: `layerpilot map-server|decide|camera`, `layerpilot router`, `layerpilot up`, and
``add_node_command``, how every `layerpilot ROLE` runs its bus node in this process.

`sim`, `link` and `depth` (cli.sim, cli.link, cli.depth) add their node commands here too,
with actions of their own (`layerpilot sim preview`, `layerpilot link takeoff 20`,
`layerpilot depth preview`); without an action they run their bus node. Every node reads the mission file (``--config``: a path or a name in
config/missions/), prints one JSON line when ready (a node that connects to something first,
the link, prints ``"status": "connecting"`` and then ``"ready"`` once connected; a refused
connection ends in ``"status": "failed"`` with the error, exit 1) and a JSON status line every
``--status-every`` seconds (the same dict goes on the bus, ``layerpilot/<vehicle>/health/<node>``,
for `layerpilot view` and recordings), and on SIGTERM/SIGINT finishes its current message, prints a
last status line and exits 0.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from dataclasses import dataclass, field
from typing import Any, Callable


def _seconds(text: str) -> float:
    """A positive, finite number of seconds (``up --duration 0`` would start every node and stop them at once)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be finite seconds > 0, got {text}")
    return value


def register(commands: argparse._SubParsersAction) -> None:
    p = add_node_command(commands, "map-server", _map_server,
                         "the map daemon: clouds in, layer sets and map queries out (one for all vehicles)",
                         flags={"snapshot": "map_server.snapshot"})
    p.add_argument("--snapshot", help="snapshot .ot path (reloaded at start); '' for none")
    p = add_node_command(commands, "decide", _decide, "layer sets + pose in, decisions and waypoints out")
    p.add_argument("--resume", action="store_true",
                   help="continue the survey saved in decide.state (path history, schedule phase, counts)")
    p.add_argument("--mission-id", default="",
                   help="the mission run this node belongs to (`up` gives one per run): a state saved in the "
                        "same run, by this node before a crash, is continued; another run's is not")

    p = add_node_command(commands, "camera", _camera,
                         "a real camera's frames on the bus: device, stream or video file, posed from the link's "
                         "poses; or a folder of geotagged photos played as camera and telemetry",
                         flags={"source": "camera.source", "calibration": "camera.calibration",
                                "file_start": "camera.file_start"})
    p.add_argument("--source", help="device index (0), stream URL (rtsp://...), video file or photo folder "
                                    "(default: camera.source)")
    p.add_argument("--calibration", help="OpenCV YAML calibration file (default: camera.calibration)")
    p.add_argument("--file-start", type=float, help="mission time (s) of a video file's first frame or a photo "
                                                    "folder's first photo (default: camera.file_start)")

    p = add_node_command(commands, "ros2", _ros2,
                         "the ROS 2 bridge: the vehicle's pose, path, target, clouds and layers as ROS 2 topics over "
                         "rmw_zenoh (no ROS install needed; docs/ros2.md)",
                         flags={"domain_id": "ros2.domain_id", "namespace": "ros2.namespace"})
    p.add_argument("--domain-id", type=int, help="ROS_DOMAIN_ID of the topics (default: ros2.domain_id, 0)")
    p.add_argument("--namespace", help="topics are <namespace>/<vehicle>/... (default: ros2.namespace, /layerpilot)")

    p = commands.add_parser("router", help="a Zenoh router for several machines (nodes then use mode = client)")
    p.add_argument("--config", help="mission file or name (for its [bus] table)")
    p.add_argument("--endpoint", help="listen endpoint (default tcp/127.0.0.1:7447)")
    p.add_argument("--secrets", default="runs/bus-secrets",
                   help="bus.security on: the mission's credentials and allow-list go here (default runs/bus-secrets)")
    p.set_defaults(func=_router)

    p = commands.add_parser("up", help="run a mission: every node as a process, status lines, restarts, clean stop")
    p.add_argument("--mission", help="mission file or name in config/missions/ (default: default)")
    p.add_argument("--endpoint", help="Zenoh endpoint the nodes meet at (default: the mission's)")
    p.add_argument("--status-every", type=float, default=2.0, help="seconds between status blocks")
    p.add_argument("--resume", action="store_true",
                   help="continue the survey where it stopped (after a battery swap): the decide nodes load "
                        "decide.state, the map server its newest snapshot")
    p.add_argument("--duration", type=_seconds, help="stop after this many seconds (default: until Ctrl-C)")
    p.add_argument("--log-dir", default="runs/logs", help="each node's log (stderr) goes to <log-dir>/<node>.log")
    p.add_argument("--secrets", help="bus.security on: each node's and the operator's credentials go here "
                                     "(mode 0700; default <log-dir>/../bus-secrets)")
    p.add_argument("--record", help="write every bus message to this MCAP file (`layerpilot replay` reads it)")
    add_ros2_record_flag(p)
    p.add_argument("--operator-can-save", action="store_true",
                   help="the operator's credentials may also query map/save (bus.operator_can_save)")
    p.set_defaults(func=_up)


def add_node_command(commands: argparse._SubParsersAction, role: str, build: Builder, help: str,
                     description: str | None = None,
                     flags: dict[str, str | tuple[str, ...]] | None = None) -> argparse.ArgumentParser:
    """`layerpilot ROLE` running the role's bus node, started by ``build(args, mission, vehicle, session)``;
    the caller adds the role's own options. ``flags``: option dest -> the mission key it overrides."""
    p = commands.add_parser(role, help=help, description=description or help)
    p.add_argument("--config", help="mission file or name in config/missions/ (default: default)")
    p.add_argument("--vehicle", default=None, help="vehicle name (default: the mission's first)")
    p.add_argument("--endpoint", help="Zenoh endpoint (default: the mission's, tcp/127.0.0.1:7447)")
    p.add_argument("--status-every", type=float, default=2.0, help="seconds between JSON status lines")
    p.add_argument("--credentials", help="this node's bus login (a JSON file `layerpilot up` writes into its "
                                         "secrets directory); without it the node joins as an open peer")
    p.set_defaults(func=_run_node, role=role, build=build, mission_flags=flags or {})
    return p


def add_ros2_record_flag(p: argparse.ArgumentParser) -> None:
    """`--ros2`: the ROS 2 channels of a recording (`up --record`, `record`)."""
    p.add_argument("--ros2", choices=("off", "beside", "only"), default="off",
                   help="ROS 2 channels (CDR, ros2msg schemas) that ros2 bag and Foxglove read as a ROS 2 bag: "
                        "beside the protobuf ones, or only them (`replay` then has nothing to read); default off")


def add_clock_flag(p: argparse.ArgumentParser) -> None:
    """``--clock-start``: where the node's stamps start on the mission clock (mission.clock)."""
    p.add_argument("--clock-start", type=float, default=0.0, metavar="SECONDS",
                   help="mission time when the vehicle's clock reads 0 (`up --resume` gives the survey's "
                        "saved mission time, so a resumed flight goes on on one clock; default 0)")


def clock_from_args(args: argparse.Namespace):
    """The mission clock ``--clock-start`` asks for; a bad value is an error naming the flag."""
    from layerpilot.mission.clock import MissionClock

    try:
        return MissionClock(args.clock_start)
    except ValueError as exc:
        raise ValueError(f"--clock-start: {exc}") from None


def mission_from_args(args: argparse.Namespace, flags: dict[str, str | tuple[str, ...]], extra: list | tuple = ()):
    """The mission file (``--config``) with every given flag in ``flags`` (dest -> mission key, or a
    tuple of keys the flag sets together) applied.

    ``extra``: more Overrides, for a flag whose value is split over several keys (``--camera WxH``).
    A bad flag value is an error naming
    the flag (``--rate must be in [0.01, 100.0], got 0.0``).
    """
    from layerpilot.missionfile import Override, load_mission

    overrides = [Override("--" + dest.replace("_", "-"), key, getattr(args, dest))
                 for dest, keys in flags.items() if getattr(args, dest, None) is not None
                 for key in ((keys,) if isinstance(keys, str) else keys)]
    return load_mission(getattr(args, "config", None), overrides + list(extra))


@dataclass
class Running:
    """A started node: its status counters, its stop(), what it tells when ready, and its blocking
    run(stop) (by default: wait for the stop, for nodes that work on their own threads)."""

    status: Callable[[], dict]
    stop: Callable[[], None] = lambda: None
    info: dict[str, Any] = field(default_factory=dict)
    run: Callable[[threading.Event], None] | None = None
    supervisor: Any = None  # nodes.supervise.Supervisor of the node's worker loops, if it has any
    ready: threading.Event | None = None  # set when the node is ready (link: autopilot heard); None = at once


Builder = Callable[..., Running]

_SAY_LOCK = threading.Lock()


def _say(**fields: Any) -> None:
    """One JSON line, written whole: the status ticker and the main thread must not interleave."""
    with _SAY_LOCK:
        sys.stdout.write(json.dumps(fields) + "\n")
        sys.stdout.flush()


def _run_node(args: argparse.Namespace) -> int:
    import logging

    from layerpilot.bus.security import open_node_session
    from layerpilot.nodes.runner import bus_config, stop_event, wait_for_stop
    from layerpilot.nodes.supervise import HealthPublisher

    mission = mission_from_args(args, args.mission_flags)
    vehicle = args.vehicle or mission.vehicles[0]
    if vehicle not in mission.vehicles:
        raise ValueError(f"--vehicle {vehicle!r}: the mission's vehicles are {mission.vehicles}")
    stop = stop_event()
    session = open_node_session(bus_config(mission.bus, args.endpoint), args.credentials)
    try:
        node = args.build(args, mission, vehicle, session)
        status = _with_health(node)
        health = HealthPublisher(session, args.role, mission.vehicles if args.role == "map-server" else [vehicle],
                                 logging.getLogger(f"layerpilot.{args.role}"))
        _say(node=args.role, vehicle=vehicle, status="ready" if node.ready is None else "connecting", **node.info)
        announcer = threading.Thread(target=_announce_ready, args=(node, stop, args.role, vehicle), daemon=True)
        announcer.start()
        ticker = threading.Thread(target=_status_loop, args=(stop, args, vehicle, status, health),
                                  daemon=True)
        ticker.start()
        if node.supervisor is not None:
            threading.Thread(target=_watch, args=(node.supervisor, stop), daemon=True).start()
        (node.run or wait_for_stop)(stop)
        stop.set()  # also when run() ended by itself (sim --duration): the ticker stops before the last line
        ticker.join()
        announcer.join()
        node.stop()
        failure = node.supervisor.failure if node.supervisor is not None else ""
        last = status()
        _say(node=args.role, vehicle=vehicle, status="failed" if failure else "stopped",
             **({"error": failure} if failure else {}), **last)
        health.publish(last)
    finally:
        session.close()
    return 1 if failure else 0


def _announce_ready(node: Running, stop: threading.Event, role: str, vehicle: str) -> None:
    """A node that must connect first (the link) said ``connecting``; it says ``ready`` only once
    connected: a node whose connection is refused never says ``ready``."""
    while node.ready is not None and not stop.is_set():
        if node.ready.wait(0.2):
            if not stop.is_set():
                _say(node=role, vehicle=vehicle, status="ready", **node.info)
            return


def _with_health(node: Running) -> Callable[[], dict]:
    """The node's counters plus its loops' heartbeat ages and the age of its last input per key."""
    if node.supervisor is None:
        return node.status
    return lambda: {**node.status(), **node.supervisor.status()}


def _watch(supervisor, stop: threading.Event) -> None:
    """Stop the node (non-zero exit, so that `up` restarts it) when a loop failed or stalled."""
    from layerpilot.nodes.runner import WAKE_PERIOD

    while not stop.wait(WAKE_PERIOD):
        if stalled := supervisor.stalled():
            supervisor.fail(f"stalled: no heartbeat from {', '.join(stalled)}")
        if supervisor.failed.is_set():
            stop.set()


def _status_loop(stop: threading.Event, args: argparse.Namespace, vehicle: str, status: Callable[[], dict],
                 health) -> None:
    """The status line on stdout and, the same dict, on the node's health key (a HealthPublisher)."""
    while not stop.wait(args.status_every):
        now = status()
        _say(node=args.role, vehicle=vehicle, **now)
        health.publish(now)


def _map_server(args, mission, vehicle, session) -> Running:
    from layerpilot.nodes.map_server import MapServer

    node = MapServer(session, mission)
    node.start()
    q, svc = node.queue, node.service
    return Running(lambda: {"received": q.received, "inserted": svc.clouds_inserted, "dropped": q.dropped,
                            "rejected": node.rejects.total, "layer_sets": node.layer_sets_published,
                            "queries": node.queries_answered, "snapshots": node.snapshots_written,
                            "leaves": node.map.stats()["leaves"], "outside": svc.points_outside},
                   node.stop, {"snapshot": node.cfg.snapshot}, supervisor=node.supervisor)


def _decide(args, mission, vehicle, session) -> Running:
    from layerpilot.nodes.decide import DecideNode

    node = DecideNode(session, vehicle, mission, resume=args.resume, mission_id=args.mission_id)
    node.start()
    return Running(lambda: {"decisions": node.seq, "reached": node.reached,
                            "distance": round(node.distance_flown, 1), "rejected": node.rejects.total,
                            "aggregates_asked": node.aggregates_answered},
                   node.stop, {"behavior": mission.decide.behavior}, supervisor=node.supervisor)


def _camera(args, mission, vehicle, session) -> Running:
    from layerpilot.nodes.camera import CameraNode

    node = CameraNode(session, vehicle, mission.camera)
    node.start()
    return Running(node.status, node.stop, {"source": mission.camera.source, "kind": node.kind},
                   run=node.run, supervisor=node.supervisor)


def _ros2(args, mission, vehicle, session) -> Running:
    from layerpilot.nodes.ros2 import Ros2Bridge

    node = Ros2Bridge(session, vehicle, mission.ros2)
    node.start()
    return Running(node.status, node.stop, {"domain_id": mission.ros2.domain_id, "namespace": mission.ros2.namespace},
                   supervisor=node.supervisor)


def _router(args: argparse.Namespace) -> int:
    from layerpilot.bus.security import open_hub
    from layerpilot.bus.session import open_session
    from layerpilot.missionfile import load_mission
    from layerpilot.nodes.runner import bus_config, stop_event, wait_for_stop

    stop = stop_event()
    mission = load_mission(args.config)
    bus = bus_config(mission.bus, args.endpoint, mode="router")
    if bus.security:  # the mission's hub: its users' logins and allow-list, as `up` makes them
        session, secrets = open_hub(bus, args.secrets, mission.vehicles,
                                    ros2=(mission.ros2.domain_id, mission.ros2.namespace) if mission.ros2.enabled
                                    else None)
    else:
        session, secrets = open_session(bus), None
    _say(node="router", status="ready", zid=str(session.zid()),
         **({"secrets": str(secrets.directory)} if secrets else {}))
    wait_for_stop(stop)
    session.close()
    return 0


def _up(args: argparse.Namespace) -> int:
    from layerpilot.nodes.up import up

    return up(args.mission, endpoint=args.endpoint, status_every=args.status_every, duration=args.duration,
              log_dir=args.log_dir, secrets_dir=args.secrets, operator_can_save=args.operator_can_save,
              resume=args.resume, record=args.record, record_ros2=args.ros2)

