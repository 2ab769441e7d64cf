"""`layerpilot plan next RUN`: the next flight over the gaps of a finished flight's map, as a QGroundControl .plan."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("plan", help="plan flights from maps: the next flight over a map's gaps")
    sub = p.add_subparsers(dest="plan_command", required=True, metavar="ACTION")
    nxt = sub.add_parser("next", help="waypoints over the unobserved and stale parts of the area of interest, "
                         "chosen by the decision maker with a behavior, written as a QGroundControl .plan")
    nxt.add_argument("run", type=Path, help="run directory (its map.ot or map.bt) or a .ot/.bt map file")
    nxt.add_argument("--behavior", default="exploration", help="preset name or .toml file (default: exploration); "
                     "its area of interest, altitude, distance ring and weights shape the plan")
    nxt.add_argument("--out", type=Path, help=".plan file to write (default: <run directory>/next.plan)")
    nxt.add_argument("--origin", type=float, nargs=3, metavar=("LAT", "LON", "ALT"),
                     help="the map frame's geodetic origin (default: the run directory's frame.json)")
    nxt.add_argument("--home", type=float, nargs=3, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"),
                     help="take-off point on the ground, map frame (default 0 0 0: a mission's map origin is home)")
    nxt.add_argument("--stale-after", type=float, default=float("inf"), metavar="S",
                     help="columns last seen more than S seconds before the map's newest observation count as gaps")
    nxt.add_argument("--footprint", type=float, help="metres the camera sees around a waypoint "
                     "(default: the behavior's r_e)")
    nxt.add_argument("--max-waypoints", type=int, default=100)
    nxt.add_argument("--coverage", type=float, default=0.95, help="share of the gaps to cover (default 0.95)")
    nxt.add_argument("--firmware", choices=("ardupilot", "px4", "generic"), default="ardupilot",
                     help="autopilot the .plan is for (QGC's firmwareType)")
    nxt.set_defaults(func=_next)


def _next(args: argparse.Namespace) -> None:
    from layerpilot.decide import area_geometry, load_behavior
    from layerpilot.decide.next_flight import plan_next_flight
    from layerpilot.eval.run_frame import read_run_frame, run_map_path
    from layerpilot.link.qgc_plan import plan_from_waypoints, write_plan
    from layerpilot.map import VoxelMap

    map_path, run_dir = run_map_path(args.run)
    frame = read_run_frame(run_dir, args.origin)  # first: a map without a place is an error before any work
    behavior = load_behavior(args.behavior)
    voxel_map = VoxelMap.load(map_path)
    home = tuple(args.home)
    columns = voxel_map.column_layers_for(area_geometry(behavior.area, home[:2], voxel_map.resolution))
    plan = plan_next_flight(columns, behavior, home=home[:2], stale_after=args.stale_after,
                            footprint=args.footprint, max_waypoints=args.max_waypoints,
                            target_coverage=args.coverage)
    out = args.out or (run_dir or map_path.parent) / "next.plan"
    write_plan(out, plan_from_waypoints(plan.waypoints, frame, home, firmware=args.firmware))
    cell = columns.geometry.resolution ** 2
    print(f"gaps: {plan.gaps.sum() * cell:.0f} m² of the area of interest unobserved or stale")
    print(f"plan: {len(plan.waypoints)} waypoints ({plan.decisions} decisions, behavior {args.behavior}) "
          f"cover {100 * plan.coverage:.1f}% of the gaps")
    print("stopped: " + {"no gaps": "no gap to cover",
                         "coverage": f"the target coverage ({100 * args.coverage:.0f}%) reached",
                         "max_waypoints": f"--max-waypoints {args.max_waypoints} reached before the target coverage "
                                          f"({100 * args.coverage:.0f}%)",
                         "max_idle": "the behavior kept choosing places already seen (max_idle choices in a row)"
                         }[plan.stopped])
    print(f"wrote {out}")
