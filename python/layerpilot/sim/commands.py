"""Simulator commands: `layerpilot sim` (run), `layerpilot sim preview`, `layerpilot bench sim`."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(commands: argparse._SubParsersAction, benches: argparse._SubParsersAction) -> None:
    p = commands.add_parser("sim", help="run the simulator (MAVLink vehicle + camera), or draw a preview",
                            description="Without an action: serve the simulated vehicle on MAVLink and "
                                        "render its camera at --rate frames per mission second.")
    p.add_argument("--config", type=Path, help="TOML file with [world] and [camera] tables (and sim keys)")
    p.add_argument("--seed", type=int, help="world seed (overrides the config)")
    p.add_argument("--url", action="append", help="MAVLink URL to serve (repeatable), default tcp:127.0.0.1:5760")
    p.add_argument("--rate", type=float, help="camera frames per mission second (default 5)")
    p.add_argument("--speed", type=float, default=1.0, help="mission clock speed vs real time")
    p.add_argument("--duration", type=float, help="stop after this many mission seconds (default: run until ^C)")
    p.add_argument("--flavour", choices=("ardupilot", "px4"), help="autopilot conventions (default ardupilot)")
    p.set_defaults(func=_run)
    sub = p.add_subparsers(dest="sim_command", metavar="ACTION")
    pv = sub.add_parser("preview", help="write a PNG: camera view, its depth, top-down map of the world")
    pv.add_argument("--config", type=Path, help="TOML file with [world] and [camera] tables")
    pv.add_argument("--seed", type=int)
    pv.add_argument("--x", type=float, default=0.0, help="vehicle east (m)")
    pv.add_argument("--y", type=float, default=0.0, help="vehicle north (m)")
    pv.add_argument("--agl", type=float, default=30.0, help="height above the terrain (m)")
    pv.add_argument("--yaw", type=float, default=30.0, help="heading, degrees counter-clockwise from east")
    pv.add_argument("--out", type=Path, default=Path("runs/sim_preview.png"))
    pv.set_defaults(func=_preview)

    b = benches.add_parser("sim", help="camera rendering frames per second at 640x480 and 320x240")
    b.add_argument("--frames", type=int, default=40)
    b.add_argument("--seed", type=int, default=0)
    b.set_defaults(func=lambda a: __import__("layerpilot.sim.bench", fromlist=["main"]).main(a.frames, a.seed))


def _load(args: argparse.Namespace):
    """SimConfig from --config with command-line overrides."""
    import dataclasses

    from layerpilot.config import from_dict, load_toml
    from layerpilot.sim.simulator import SimConfig

    data = load_toml(args.config) if args.config else {}
    config = from_dict(SimConfig, data, "sim")
    if args.seed is not None:
        config = dataclasses.replace(config, world=dataclasses.replace(config.world, seed=args.seed))
    overrides = {k: getattr(args, a, None) for k, a in (("frame_rate_hz", "rate"), ("flavour", "flavour"))}
    if getattr(args, "url", None):
        overrides["urls"] = tuple(args.url)
    return dataclasses.replace(config, **{k: v for k, v in overrides.items() if v is not None})


def _preview(args: argparse.Namespace) -> None:
    from layerpilot.sim.preview import write_preview
    from layerpilot.sim.world import World

    config = _load(args)
    info = write_preview(World(config.world), config.camera, args.x, args.y, args.agl, args.yaw, args.out)
    print(f"wrote {info['path']} (depth {info['depth_min_m']:.1f}-{info['depth_max_m']:.1f} m, "
          f"sky {100 * info['sky_fraction']:.0f}%, {info['renderer']})")


def _run(args: argparse.Namespace) -> None:
    import time

    from layerpilot.sim.simulator import Simulator

    config = _load(args)
    try:
        sim = Simulator(config)
    except OSError as exc:  # the MAVLink port is taken or the address is wrong
        raise ValueError(str(exc)) from None
    with sim:
        hosts = ", ".join(f"{u} -> {h}:{p}" for u, (h, p) in zip(config.urls, sim.endpoint.addresses))
        s = sim.world.stats()
        print(f"layerpilot sim: world seed {config.world.seed} ({s['trees']} trees), MAVLink on {hosts}, "
              f"camera {config.camera.width}x{config.camera.height} at {config.frame_rate_hz:g} Hz, "
              f"{sim.renderer.renderer_name}", flush=True)
        last = [time.monotonic(), 0]

        def on_frame(stamp: float, frame) -> None:
            now = time.monotonic()
            if now - last[0] >= 5.0:
                x, y, z = frame.pose.centre
                print(f"t={stamp:8.2f} s  frames={sim.frames}  {(sim.frames - last[1]) / (now - last[0]):.1f} fps  "
                      f"vehicle ({x:.1f}, {y:.1f}, {z:.1f}) clients={sim.endpoint.clients}", flush=True)
                last[:] = [now, sim.frames]

        sim.run(on_frame, speed=args.speed, duration=args.duration)
        print(f"layerpilot sim: stopped at t={sim.time:.2f} s after {sim.frames} frames", flush=True)
