"""`layerpilot link`: the link node, or one action for bench tests on a real autopilot or SITL
(`goto X Y Z`, `takeoff ALT`, `land`, `rtl`, `upload PLAN`, `download PLAN`, `fly-plan PLAN`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from layerpilot.cli.nodes import Running, add_clock_flag, add_node_command, clock_from_args


def register(commands: argparse._SubParsersAction) -> None:
    p = add_node_command(commands, "link", _node, "MAVLink flight link (ArduPilot GUIDED, PX4 OFFBOARD): the link node, "
                         "or an action (goto, takeoff, land, rtl)",
                         "Without an action: the link node, flying the bus's waypoints and publishing the pose. "
                         "With one: connect, do it, wait until done, print the telemetry.", flags=LINK_FLAGS)
    p.add_argument("--mavlink", metavar="URL",
                   help="tcp:HOST:PORT (ArduPilot SITL 5760), udpin:0.0.0.0:14540 (PX4 SITL), /dev/ttyUSB0:57600 "
                        "(default: the mission's for this vehicle)")
    add_clock_flag(p)
    p.add_argument("--sysid", type=int, help="our MAVLink system id (default 1, like a companion)")
    p.add_argument("--compid", type=int, help="our MAVLink component id (default 191, onboard computer)")
    p.add_argument("--timeout", type=float,
                   help="the longest any one wait may take: the connection, readiness, arming, a mode change "
                        "and, for an action, the action itself (default: 30 s to connect, 120 s to be ready, "
                        "10 s to arm, 5 s for a mode, and each action's own bound)")
    p.add_argument("--tolerance", type=float, help="arrival tolerance in metres (default 1)")
    sub = p.add_subparsers(dest="link_command", metavar="ACTION")
    goto = sub.add_parser("goto", help="fly to map-frame X Y Z (ENU metres from the autopilot's local origin)")
    for axis in ("x", "y", "z"):
        goto.add_argument(axis, type=float)
    goto.add_argument("--yaw", type=float, default=None, help="heading in degrees, counter-clockwise from east")
    takeoff = sub.add_parser("takeoff", help="GUIDED/OFFBOARD, arm and climb to ALT metres above home")
    takeoff.add_argument("alt", type=float)
    sub.add_parser("land", help="land where the vehicle is and wait until it disarms")
    sub.add_parser("rtl", help="return to launch and wait until it disarms")
    for action in sub.choices.values():
        action.set_defaults(func=_act)
    upload = sub.add_parser("upload", help="upload a QGroundControl .plan as the vehicle's mission "
                            "(MISSION_ITEM_INT protocol) and wait for its MISSION_ACK")
    upload.add_argument("plan", type=Path, help=".plan file (e.g. from `layerpilot plan next`)")
    download = sub.add_parser("download", help="read the vehicle's mission back into a QGroundControl .plan")
    download.add_argument("plan", type=Path, help=".plan file to write")
    fly = sub.add_parser("fly-plan", help="upload a .plan, take off in GUIDED to its first item's altitude if on "
                         "the ground, fly it in AUTO and wait until its last item is reached (ArduPilot)")
    fly.add_argument("plan", type=Path, help=".plan file (e.g. from `layerpilot plan next`)")
    for transfer in (upload, download, fly):
        transfer.add_argument("--item-timeout", type=float, default=1.5,
                              help="seconds to wait for each answer of the vehicle before sending again (default 1.5)")
        transfer.add_argument("--retries", type=int, default=3,
                              help="sends again per answer before giving up (default 3)")
        transfer.set_defaults(func=_transfer)
    fly.set_defaults(func=_act)


LINK_FLAGS = {"mavlink": "link.link.url", "sysid": "link.link.source_system", "compid": "link.link.source_component",
              "timeout": ("link.link.connect_timeout_s", "link.link.ready_timeout_s", "link.link.arm_timeout_s",
                          "link.link.mode_timeout_s"),
              "tolerance": "link.link.arrival_tolerance_m"}


def _node(args, mission, vehicle, session) -> Running:
    from layerpilot.missionfile import geofence_for
    from layerpilot.nodes.link import LinkNode

    node = LinkNode(session, vehicle, link_settings(args, mission, vehicle), geofence_for(mission),
                    clock_from_args(args), fleet=mission.vehicles)
    link = node.link

    def status() -> dict:
        out = {"phase": node.phase, "waypoints": node.waypoints, "rejected": node.rejects.total,
               "refused": dict(link.refused),  # by the geofence and the fleet's separation, per kind
               "pose": node.pose_state(), "poses": node.poses,
               "telemetry": link.telemetry().line() if link.flavour else "no autopilot heard yet"}
        if node.phase == "waiting for the autopilot":
            out["missing"] = link.missing()  # what keeps the autopilot from being ready
        if node.end:
            out["end"] = node.end  # the mission's end action: "RTL acknowledged (...)" or why not
        return out

    return Running(status, node.stop, {"mavlink": node.cfg.link.url, "geofence": link.geofence.describe()},
                   node.run, supervisor=node.supervisor, ready=node.connected)


def link_settings(args: argparse.Namespace, mission, vehicle: str):
    """The mission's link settings; the autopilot's URL is --mavlink, else for a camera-only mission
    or a real camera (``camera.source`` not ``sim``) the real autopilot's (``[link.link].url``), else
    this vehicle's simulator."""
    import dataclasses

    settings = mission.link
    if not args.mavlink and not mission.camera_only and mission.camera.source == "sim":
        settings = dataclasses.replace(settings, link=dataclasses.replace(settings.link,
                                                                          url=mission.mavlink_url(vehicle)))
    return settings


def _act(args: argparse.Namespace) -> int:
    """One action; every wait is bounded by --timeout when given. Exit 0 when done, 1 with one line on
    stderr when the vehicle or the link refused or timed out (2 for a bad flag, from main)."""
    import dataclasses
    import logging

    from layerpilot.cli.nodes import mission_from_args
    from layerpilot.missionfile import geofence_for

    plan = _plan_to_fly(args) if args.link_command == "fly-plan" else None  # a bad file: before connecting
    mission = mission_from_args(args, LINK_FLAGS)
    config = link_settings(args, mission, args.vehicle or mission.vehicles[0]).link
    bound = {} if args.timeout is None else {"timeout": args.timeout}
    if args.timeout is not None:  # a command's COMMAND_ACK tries, all of them together, too
        config = dataclasses.replace(config, command_timeout_s=min(config.command_timeout_s,
                                                                   args.timeout / (config.command_retries + 1)))
    action = args.link_command
    # each report prints once, on stdout as `link: ...` (on_event below); the logger's copy would repeat
    # every warning on stderr, where only the one error line belongs
    logger, quiet = logging.getLogger("layerpilot.link"), logging.NullHandler()
    logger.addHandler(quiet)
    logger.propagate = False
    try:
        return _fly(args, action, config, bound, geofence_for(mission), plan)
    finally:
        logger.removeHandler(quiet)
        logger.propagate = True


def _fly(args: argparse.Namespace, action: str, config, bound: dict, geofence, plan=None) -> int:
    import math
    import sys

    from layerpilot.link.link import FlightLink, LinkError
    from layerpilot.link.mission_transfer import MissionTransferError

    if plan is not None:
        try:
            _upload_for_auto(args, config, plan, geofence)
        except MissionTransferError as exc:
            print(f"layerpilot link {action}: error: {exc}", file=sys.stderr, flush=True)
            return 1
    with FlightLink(config, on_event=lambda text: print(f"link: {text}", flush=True), geofence=geofence) as link:
        try:
            link.connect()
            link.wait_ready()
            if plan is not None:
                _fly_mission(link, plan, bound)
            elif action == "takeoff":
                link.start_guided()
                link.arm()
                link.takeoff(args.alt, **bound)
            elif action == "goto":
                if not link.armed:
                    raise LinkError("the vehicle is not armed: `layerpilot link takeoff ALT` first")
                link.start_guided()
                link.goto(args.x, args.y, args.z, yaw=None if args.yaw is None else math.radians(args.yaw),
                          **bound)
            elif action == "land":
                link.land(**bound)  # refused on a disarmed vehicle (as rtl): it is on the ground already
            else:
                link.rtl(**bound)  # refused on a disarmed vehicle: on the ground, nothing to return from
        except (LinkError, ValueError) as exc:
            if link.flavour is not None:  # telemetry only from an autopilot actually heard
                print(link.telemetry().line(), flush=True)
            print(f"layerpilot link {action}: error: {exc}", file=sys.stderr, flush=True)
            return 1
        print(link.telemetry().line(), flush=True)
    print(f"{action}: done")
    return 0


def _plan_to_fly(args: argparse.Namespace):
    """The plan for ``fly-plan``; ValueError (exit 2) for a bad file, an empty plan or bad flags."""
    from layerpilot.link.qgc_plan import read_plan

    if not args.item_timeout > 0 or args.retries < 0:
        raise ValueError(f"--item-timeout must be > 0 and --retries >= 0, got {args.item_timeout}, {args.retries}")
    plan = read_plan(args.plan)
    if not plan.items:
        raise ValueError(f"{args.plan}: the plan has no mission items to fly")
    return plan


def _flown(plan, frame, home_z: float) -> list:
    """Where the items of ``plan`` take the vehicle, in order from home: (item number, item, map-frame point in
    ``frame``, where home is at ``home_z``). Lat and lon 0 are where the vehicle is (MissionItem.place, as
    ArduPilot's AUTO and the simulator's fly them); a LAND ends on the ground below its point, an RTL at home;
    DO_* and CONDITION_* items fly nowhere and are left out."""
    import numpy as np

    from layerpilot.link.mission_transfer import LAND, RTL
    from layerpilot.link.modes import FIRST_ITEM

    x, y, _ = frame.from_geodetic(plan.home[0], plan.home[1], 0.0)
    home = np.array([float(x), float(y), home_z])
    here, flown = home, []
    for number, item in enumerate(plan.items, 1):
        if item.command == RTL:
            here = home
        elif item.flies:
            here = item.place(frame, home_z, here)
            if item.command == LAND:
                here[2] = home_z
        else:
            continue
        flown.append((number, item, here))
    return flown


def _upload_for_auto(args: argparse.Namespace, config, plan, geofence) -> None:
    """Upload ``plan`` over a connection of its own (closed before the flight link opens the URL); only to
    ArduPilot or PX4, whose AUTO or AUTO.MISSION the flight uses, and only when every place the plan flies to
    lies inside the geofence (placed in the vehicle's frame; a LAND's only in the area: it ends on the ground,
    below the altitude floor; an RTL's is home). MissionTransferError when the vehicle does not answer or refuses, or
    an item is outside."""
    from layerpilot.link.connection import open_connection
    from layerpilot.link.geofence import OutsideGeofence
    from layerpilot.link.mission_transfer import LAND, RTL, MissionTransferError, upload_mission, vehicle_frame
    from layerpilot.link.qgc_plan import ARDUPILOT, PX4, mission_items

    wait = config.connect_timeout_s if args.timeout is None else args.timeout
    conn = open_connection(config.url, config.source_system, config.source_component, config.baud)
    try:
        heartbeat = _autopilot_heartbeat(conn, config, wait)
        if heartbeat.autopilot not in (ARDUPILOT, PX4):
            raise MissionTransferError(f"fly-plan flies a stored mission in ArduPilot's AUTO or PX4's AUTO.MISSION; "
                                       f"this autopilot (MAV_AUTOPILOT {heartbeat.autopilot}) is neither (upload it "
                                       "with `layerpilot link upload` and fly it there)")
        target = (heartbeat.get_srcSystem(), heartbeat.get_srcComponent())
        frame, home_z = vehicle_frame(conn, target, wait)
        for i, item, point in _flown(plan, frame, home_z):
            try:
                if item.command in (LAND, RTL):
                    geofence.check_area(*point)
                else:
                    geofence.check(*point, home_z)
            except OutsideGeofence as exc:
                raise MissionTransferError(f"item {i} of the plan: {exc} (nothing uploaded)") from None
        upload_mission(conn, mission_items(plan, heartbeat.autopilot), target, timeout=args.item_timeout,
                       retries=args.retries)
    finally:
        conn.close()
    print(f"fly-plan: {len(plan.items)} mission items accepted by system {heartbeat.get_srcSystem()}", flush=True)


def _fly_mission(link, plan, bound: dict) -> None:
    """Take off in GUIDED/OFFBOARD to the first flown item's altitude when on the ground, then AUTO (PX4:
    AUTO.MISSION) until the last item is reached (ArduPilot numbers the plan's items from 1: item 0 is home;
    PX4 from 0) or, when it is a LAND or an
    RTL, until the vehicle disarmed on the ground there. Without --timeout the flight may take 60 s plus
    3 s per metre of the plan's path from home."""
    import numpy as np

    from layerpilot.geodesy import LocalFrame
    from layerpilot.link.link import ControlLost
    from layerpilot.link.mission_transfer import LAND, RTL
    from layerpilot.link.modes import FIRST_ITEM

    flown = _flown(plan, LocalFrame(*plan.home), 0.0)
    path = np.vstack([[0.0, 0.0, 0.0]] + [point for _, _, point in flown])
    timeout = bound.get("timeout", 60.0 + 3.0 * float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()))
    if not link.armed:
        link.start_guided()
        link.arm()
        link.takeoff(float(flown[0][2][2]) if flown else 0.0, **bound)
    n, current, first = len(plan.items), [0], FIRST_ITEM[link.flavour]

    def progress(kind: str, seq: int) -> None:  # the plan's item numbers, 1..n, whatever the autopilot's
        current[0] = seq - first + 1 if kind == "current" else current[0]
        print(f"mission: {'flying to' if kind == 'current' else 'reached'} item {seq - first + 1} of {n}",
              flush=True)

    try:
        link.fly_mission(n - 1 + first, timeout, progress)
    except ControlLost as exc:  # a final LAND or RTL ends in a disarm on the ground: the mission is done
        if not (exc.kind == "disarmed" and current[0] == n and plan.items[-1].command in (LAND, RTL)):
            raise
        print(f"mission: item {n} of {n} ({'LAND' if plan.items[-1].command == LAND else 'RTL'}) ended on the "
              "ground, disarmed", flush=True)


def _autopilot_heartbeat(conn, config, wait: float):
    from layerpilot.link.mission_transfer import MissionTransferError

    heartbeat = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=wait,
                                condition="HEARTBEAT.autopilot != 8")  # 8: MAV_AUTOPILOT_INVALID (a GCS)
    if heartbeat is None:
        raise MissionTransferError(f"no autopilot HEARTBEAT on {config.url} within {wait:g} s")
    return heartbeat


def _transfer(args: argparse.Namespace) -> int:
    """Upload or download a .plan: exit 0 once done, 1 with one line on stderr when the vehicle did not answer
    or refused (2 for a bad flag or a bad file, from main)."""
    import sys

    from layerpilot.cli.nodes import mission_from_args
    from layerpilot.link.connection import open_connection
    from layerpilot.link.mission_transfer import MissionTransferError, download_mission, upload_mission
    from layerpilot.link.qgc_plan import mission_items, plan_from_mission, read_plan, write_plan

    if not args.item_timeout > 0 or args.retries < 0:
        raise ValueError(f"--item-timeout must be > 0 and --retries >= 0, got {args.item_timeout}, {args.retries}")
    action = args.link_command
    plan = read_plan(args.plan) if action == "upload" else None
    mission = mission_from_args(args, LINK_FLAGS)
    config = link_settings(args, mission, args.vehicle or mission.vehicles[0]).link
    wait = config.connect_timeout_s if args.timeout is None else args.timeout
    bounds = {"timeout": args.item_timeout, "retries": args.retries}
    conn = open_connection(config.url, config.source_system, config.source_component, config.baud)
    try:
        heartbeat = _autopilot_heartbeat(conn, config, wait)
        target = (heartbeat.get_srcSystem(), heartbeat.get_srcComponent())
        if plan is not None:
            upload_mission(conn, mission_items(plan, heartbeat.autopilot), target, **bounds)
        else:
            items = download_mission(conn, target, **bounds)
            plan = plan_from_mission(items, heartbeat.autopilot, _home(conn, heartbeat.autopilot, wait))
            write_plan(args.plan, plan)
    except MissionTransferError as exc:
        print(f"layerpilot link {action}: error: {exc}", file=sys.stderr, flush=True)
        return 1
    finally:
        conn.close()
    done = "accepted by" if action == "upload" else f"written to {args.plan} from"
    print(f"{action}: {len(plan.items)} mission items {done} system {target[0]} on {config.url}")
    return 0


def _home(conn, autopilot: int, wait: float) -> tuple[float, float, float] | None:
    """Home from the vehicle's HOME_POSITION (not needed for ArduPilot, whose mission item 0 is home)."""
    from layerpilot.link.mission_transfer import MissionTransferError
    from layerpilot.link.qgc_plan import ARDUPILOT

    if autopilot == ARDUPILOT:
        return None
    msg = conn.recv_match(type="HOME_POSITION", blocking=True, timeout=wait)
    if msg is None:
        raise MissionTransferError(f"no HOME_POSITION within {wait:g} s (the .plan needs the home)")
    return (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
