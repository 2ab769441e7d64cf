"""Simulator commands: `layerpilot sim` (the simulator node), `layerpilot sim preview`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from layerpilot.cli.nodes import Running, add_clock_flag, add_node_command, clock_from_args

if TYPE_CHECKING:
    from layerpilot.geodesy import LocalFrame


def register(commands: argparse._SubParsersAction) -> None:
    p = add_node_command(commands, "sim", _node, "the simulator node: MAVLink vehicle + camera frames on the bus; "
                         "or an action (preview)",
                         "Without an action: serve the mission's simulated vehicle on MAVLink and publish "
                         "its camera frames on the bus (with camera_only = true: render the pose a real "
                         "autopilot reports).", flags={**SIM_FLAGS, "flavour": "sim.flavour", "speed": "speed"})
    _world_args(p)
    p.add_argument("--mavlink", metavar="URL", help="MAVLink URL to serve (default: the mission's for this vehicle)")
    p.add_argument("--flavour", choices=("ardupilot", "px4"), help="autopilot conventions (default: the mission's)")
    p.add_argument("--speed", type=float, help="mission clock speed vs real time (default: the mission's)")
    p.add_argument("--duration", type=float, help="stop after this many mission seconds (default: until SIGTERM)")
    add_clock_flag(p)  # camera-only frames take the poses' stamps, already on the mission clock
    p.add_argument("--write-frame", metavar="DIR", type=Path,
                   help="write DIR/frame.json: where the map frame (the EKF origin, home on the ground) lies on "
                        "the Earth, for `layers export` and `plan next` (`up` gives the map snapshot's directory)")
    sub = p.add_subparsers(dest="sim_command", metavar="ACTION")
    pv = sub.add_parser("preview", help="write a PNG: camera view, its depth, top-down map of the world")
    # SUPPRESS: given before or after `preview`, these keep their value
    pv.add_argument("--config", default=argparse.SUPPRESS, help="mission file or name (its [sim] table)")
    _world_args(pv, default=argparse.SUPPRESS)
    pv.add_argument("--x", type=float, default=0.0, help="vehicle east (m)")
    pv.add_argument("--y", type=float, default=0.0, help="vehicle north (m)")
    pv.add_argument("--agl", type=float, default=30.0, help="height above the terrain (m)")
    pv.add_argument("--yaw", type=float, default=30.0, help="heading, degrees counter-clockwise from east")
    pv.add_argument("--out", type=Path, default=Path("runs/sim_preview.png"))
    pv.set_defaults(func=_preview)


SIM_FLAGS = {"seed": "sim.world.seed", "rate": "sim.frame_rate_hz"}  # option dest -> mission key


def _world_args(p: argparse.ArgumentParser, default: Any = None) -> None:
    p.add_argument("--seed", type=int, default=default, help="world seed (default: the mission's)")
    p.add_argument("--rate", type=float, default=default, help="camera frames per mission second (default: the mission's)")


def _node(args, mission, vehicle, session) -> Running:
    import dataclasses

    from layerpilot.nodes.sim import CameraOnlyNode, SimNode

    if mission.camera_only:
        if args.write_frame is not None:
            raise ValueError("--write-frame: with camera_only = true the vehicle is another autopilot, whose EKF "
                             "origin this node does not know")
        node = CameraOnlyNode(session, vehicle, mission.simulator)
        return Running(lambda: {"frames": node.frames, "rejected": node.rejects.total},
                       info={"camera_only": True}, run=node.run)
    config = dataclasses.replace(mission.simulator, urls=(args.mavlink or mission.mavlink_url(vehicle),))
    try:
        node = SimNode(session, vehicle, config, speed=mission.speed, duration=args.duration,
                       clock=clock_from_args(args))
    except OSError as exc:  # the MAVLink port is taken or the address is wrong
        raise ValueError(f"MAVLink {config.urls[0]}: {exc}") from None
    info = node.describe()
    if args.write_frame is not None:
        info["frame"] = _write_frame(args.write_frame, node.sim.endpoint.ekf_frame)
    return Running(lambda: {"frames": node.frames, "time": round(node.clock(node.sim.time), 2)},
                   info=info, run=node.run)


def _write_frame(run_dir: Path, frame: LocalFrame) -> str:
    """frame.json in ``run_dir``; a directory that cannot be written is logged, not fatal (the vehicle flies
    without it, as the map server serves on when its snapshot cannot be written)."""
    import logging

    from layerpilot.eval.run_frame import write_run_frame

    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        return str(write_run_frame(run_dir, frame))
    except OSError as exc:
        logging.getLogger("layerpilot.sim").warning("--write-frame: cannot write frame.json: %s", exc)
        return ""


def _preview(args: argparse.Namespace) -> None:
    from layerpilot.cli.nodes import mission_from_args
    from layerpilot.eval.pictures.sim_preview import write_preview
    from layerpilot.sim.world import World

    config = mission_from_args(args, SIM_FLAGS).sim
    info = write_preview(World(config.world), config.camera, args.x, args.y, args.agl, args.yaw, args.out)
    print(f"wrote {info['path']} (depth {info['depth_min_m']:.1f}-{info['depth_max_m']:.1f} m, "
          f"sky {100 * info['sky_fraction']:.0f}%, {info['renderer']})")
