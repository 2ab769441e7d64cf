"""`layerpilot link --mavlink URL goto X Y Z | takeoff ALT | land`: bench tests on a real autopilot or SITL."""

from __future__ import annotations

import argparse


def register(commands: argparse._SubParsersAction, benches: argparse._SubParsersAction) -> None:
    p = commands.add_parser("link", help="fly the vehicle over MAVLink (ArduPilot GUIDED, PX4 OFFBOARD)")
    p.add_argument("--mavlink", default="tcp:127.0.0.1:5760", metavar="URL",
                   help="tcp:HOST:PORT (ArduPilot SITL 5760), udpin:0.0.0.0:14540 (PX4 SITL), /dev/ttyUSB0:57600")
    p.add_argument("--sysid", type=int, default=1, help="our MAVLink system id (default 1, like a companion)")
    p.add_argument("--compid", type=int, default=191, help="our MAVLink component id (default 191, onboard computer)")
    p.add_argument("--timeout", type=float, default=60.0, help="seconds to wait for the vehicle to be ready")
    p.add_argument("--tolerance", type=float, default=1.0, help="arrival tolerance in metres")
    sub = p.add_subparsers(dest="link_command", required=True, metavar="ACTION")
    goto = sub.add_parser("goto", help="fly to map-frame X Y Z (ENU metres from the autopilot's local origin)")
    for axis in ("x", "y", "z"):
        goto.add_argument(axis, type=float)
    goto.add_argument("--yaw", type=float, default=None, help="heading in degrees, counter-clockwise from east")
    takeoff = sub.add_parser("takeoff", help="GUIDED/OFFBOARD, arm and climb to ALT metres above home")
    takeoff.add_argument("alt", type=float)
    sub.add_parser("land", help="land where the vehicle is and wait until it disarms")
    sub.add_parser("rtl", help="return to launch and wait until it disarms")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import math

    from layerpilot.link.config import LinkConfig
    from layerpilot.link.link import FlightLink, LinkError

    config = LinkConfig(url=args.mavlink, source_system=args.sysid, source_component=args.compid,
                        ready_timeout_s=args.timeout, arrival_tolerance_m=args.tolerance)
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
