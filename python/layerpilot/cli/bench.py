"""`layerpilot bench map|decide|view|depth|sim|bus|scale|photos|mission`: every speed claim against its reference (layerpilot.bench)."""

from __future__ import annotations

import argparse
from pathlib import Path

from layerpilot.cli.depth import size


def register(commands: argparse._SubParsersAction) -> None:
    bench = commands.add_parser("bench", help="speed measurements side by side with the reference")
    benches = bench.add_subparsers(dest="bench", required=True, metavar="WHAT")

    b = benches.add_parser("map", help="insertion speed vs OctoMap, voxels identical to it, column layers, memory")
    b.add_argument("--frames", type=int, default=6)
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--world-size", type=float, default=1000.0,
                   help="metres; memory after surveying a world this wide (0: skip)")
    b.set_defaults(func=_map)

    b = benches.add_parser("decide", help="layers + decision tick on 512, 1024 and 2048 square grids")
    b.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    b.add_argument("--repeat", type=int, default=30)
    b.add_argument("--behavior", default="balanced")
    b.set_defaults(func=_decide)

    b = benches.add_parser("view", help="the view_gain layer at 256 and 512 square grids vs fringe and a bare correlation")
    b.add_argument("--sizes", type=int, nargs="+", default=[256, 512])
    b.add_argument("--repeat", type=int, default=10)
    b.set_defaults(func=_view)

    b = benches.add_parser("depth", help="stereo precision, coverage, error and pairs/s on rendered pairs")
    b.add_argument("--sizes", type=lambda t: [size(s) for s in t.split(",")], default=[(640, 480), (320, 240)])
    b.add_argument("--repeats", type=int, default=3)
    b.add_argument("--seed", type=int, default=0)
    b.set_defaults(func=_depth)

    b = benches.add_parser("sim", help="camera rendering frames per second at 640x480 and 320x240")
    b.add_argument("--frames", type=int, default=40)
    b.add_argument("--seed", type=int, default=0)
    b.set_defaults(func=_sim)

    b = benches.add_parser("scale", help="insertion, memory, layer query and decision as the survey area grows")
    b.add_argument("--sides", type=float, nargs="+", default=[100.0, 250.0, 500.0, 1000.0], help="area sides in m")
    b.add_argument("--repeat", type=int, default=15)
    b.add_argument("--seed", type=int, default=0)
    b.set_defaults(func=_scale)

    b = benches.add_parser("bus", help="map server on loopback: layer-query round trip, cloud throughput")
    b.add_argument("--seconds", type=float, default=5.0, help="seconds of clouds to send")
    b.add_argument("--rate", type=float, default=10.0, help="clouds per second offered")
    b.set_defaults(func=_bus)

    b = benches.add_parser("photos", help="stereo from real photos vs a reference cloud, adjusted vs refined vs raw poses")
    b.add_argument("--folder", type=Path, help="photo folder (default: ../shared/data/brighton_beach/images "
                   "from the working directory, else beside the source checkout)")
    b.add_argument("--reference", type=Path, help="LAS/LAZ reference cloud (default: that folder's model.laz)")
    b.add_argument("--width", type=int, default=1000, help="working image width in pixels")
    b.set_defaults(func=_photos)

    b = benches.add_parser("mission", help="a lock-step mission, stages overlapped vs sequential (same bytes?)")
    b.add_argument("--config", default=None, help="mission file or name (default: the default mission)")
    b.add_argument("--duration", type=float, default=600.0, help="mission seconds of each run")
    b.add_argument("--camera", type=size, default=(320, 240), help="camera size WxH")
    b.set_defaults(func=_mission)


def _map(args: argparse.Namespace) -> None:
    from layerpilot.bench.map import main

    main(args.frames, args.seed, args.world_size)


def _decide(args: argparse.Namespace) -> None:
    from layerpilot.bench.decide import print_decide_bench, run_decide_bench

    print_decide_bench(run_decide_bench(args.sizes, args.repeat, args.behavior))


def _view(args: argparse.Namespace) -> None:
    from layerpilot.bench.view_gain import print_view_bench, run_view_bench

    print_view_bench(run_view_bench(args.sizes, args.repeat))


def _depth(args: argparse.Namespace) -> None:
    from layerpilot.bench.depth import main

    if args.repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {args.repeats}")
    main(args.sizes, args.repeats, args.seed)


def _sim(args: argparse.Namespace) -> int:
    from layerpilot.bench.sim import main

    return main(args.frames, args.seed)


def _scale(args: argparse.Namespace) -> None:
    from layerpilot.bench.scale import print_scale_bench, run_scale_bench

    if args.repeat < 1:
        raise ValueError(f"--repeat must be >= 1, got {args.repeat}")
    print_scale_bench(run_scale_bench(args.sides, args.repeat, args.seed))


def _bus(args: argparse.Namespace) -> int:
    from layerpilot.bench.bus import main

    return main(args.seconds, args.rate)


def _photos(args: argparse.Namespace) -> int:
    from layerpilot.bench.photos import main

    return main(args.folder, args.reference, args.width)


def _mission(args: argparse.Namespace) -> int:
    from layerpilot.bench.mission import main
    from layerpilot.missionfile import Override, load_mission

    mission = load_mission(args.config, [
        Override("--duration", "evaluation.duration", args.duration),
        Override("--camera", "sim.camera.width", args.camera[0]),
        Override("--camera", "sim.camera.height", args.camera[1]),
        Override("--state", "decide.state", "")])  # a bench must not overwrite a saved survey
    return main(mission)
