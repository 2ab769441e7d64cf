"""`layerpilot link`: the link node, or one action for bench tests on a real autopilot or SITL
(`goto X Y Z`, `takeoff ALT`, `land`, `rtl`)."""

from __future__ import annotations

import argparse
from typing import Any

from layerpilot.cli.nodes import Running, add_node_command


def register(commands: argparse._SubParsersAction) -> None:
    p = add_node_command(commands, "link", _node, "MAVLink flight link (ArduPilot GUIDED, PX4 OFFBOARD): the link node, "
                         "or an action (goto, takeoff, land, rtl)",
                         "Without an action: the link node, flying the bus's waypoints and publishing the pose. "
                         "With one: connect, do it, wait until done, print the telemetry.")
    p.add_argument("--mavlink", metavar="URL",
                   help="tcp:HOST:PORT (ArduPilot SITL 5760), udpin:0.0.0.0:14540 (PX4 SITL), /dev/ttyUSB0:57600 "
                        "(default: the mission's for this vehicle)")
    p.add_argument("--sysid", type=int, help="our MAVLink system id (default 1, like a companion)")
    p.add_argument("--compid", type=int, help="our MAVLink component id (default 191, onboard computer)")
    p.add_argument("--timeout", type=float, help="seconds to wait for the vehicle to be ready (default 60)")
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


def _node(args, mission, tables, vehicle, session) -> Running:
    from layerpilot.nodes.link import LinkNode

    node = LinkNode(session, vehicle, link_node_config(args, mission, tables, vehicle))
    return Running(lambda: {"waypoints": node.waypoints, "rejected": node.rejects.total,
                            "telemetry": node.link.telemetry().line()}, node.stop,
                   {"mavlink": node.cfg.link.url}, node.run)


def link_node_config(args: argparse.Namespace, mission, tables: dict[str, Any], vehicle: str):
    """The mission's ``[link]`` table with the command line's overrides.

    The autopilot's URL: --mavlink, else for a camera-only mission the real autopilot's
    (``[link.link].url``), else this vehicle's simulator.
    """
    from layerpilot.config import from_dict
    from layerpilot.nodes.link import LinkNodeConfig

    data = dict(tables.get("link", {}))
    link = dict(data.get("link", {}))
    if args.mavlink or not mission.camera_only:
        link["url"] = args.mavlink or mission.mavlink_url(vehicle)
    given = {"source_system": args.sysid, "source_component": args.compid, "ready_timeout_s": args.timeout,
             "arrival_tolerance_m": args.tolerance}
    data["link"] = {**link, **{k: v for k, v in given.items() if v is not None}}
    return from_dict(LinkNodeConfig, data, "link")


def _act(args: argparse.Namespace) -> int:
    import math

    from layerpilot.link.link import FlightLink, LinkError
    from layerpilot.nodes.mission import load_mission

    mission, tables = load_mission(args.config)
    config = link_node_config(args, mission, tables, args.vehicle or mission.vehicles[0]).link
    with FlightLink(config, on_event=lambda text: print(f"link: {text}", flush=True)) as link:
        try:
            link.connect()
            link.wait_ready()
            if args.link_command == "takeoff":
                link.start_guided()
                link.arm()
                link.takeoff(args.alt)
            elif args.link_command == "goto":
                if not link.armed:
                    raise LinkError("the vehicle is not armed: `layerpilot link takeoff ALT` first")
                link.start_guided()
                link.goto(args.x, args.y, args.z, yaw=None if args.yaw is None else math.radians(args.yaw))
            elif args.link_command == "land":
                link.land()
            else:
                link.rtl()
        except (LinkError, ValueError) as exc:
            print(f"layerpilot link: error: {exc}", flush=True)
            return 1
        finally:
            print(link.telemetry().line(), flush=True)
    print(f"{args.link_command}: done")
    return 0
