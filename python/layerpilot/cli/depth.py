"""Depth commands: `layerpilot depth` (the depth node), `layerpilot depth preview`."""

from __future__ import annotations

import argparse
from pathlib import Path

from layerpilot.cli.nodes import Running, add_node_command


def size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"size {text!r}: at least 16x16")
    return w, h


def register(commands: argparse._SubParsersAction) -> None:
    p = add_node_command(commands, "depth", _node, "depth from the moving camera: the depth node (camera frames in, "
                         "point clouds out), or an action (preview)")
    sub = p.add_subparsers(dest="depth_command", metavar="ACTION")
    prev = sub.add_parser("preview", help="PNG panel of one rendered pair: rectified views, disparity, depth, error")
    prev.add_argument("--out", type=Path, default=Path("runs/depth_preview.png"))
    prev.add_argument("--size", type=size, default=(640, 480), help="WIDTHxHEIGHT (default 640x480)")
    prev.add_argument("--pair", type=int, default=0, help="index into the bench's fixed pair set")
    prev.add_argument("--seed", type=int, default=0, help="world seed")
    prev.set_defaults(func=_preview)


def _node(args, mission, vehicle, session) -> Running:
    from layerpilot.nodes.depth import DepthNode

    node = DepthNode(session, vehicle, mission)
    node.start()
    q = node.queue
    return Running(lambda: {"frames": q.received, "dropped": q.dropped, "clouds": node.clouds,
                            "rejected": node.rejects.total, **node.status()}, node.stop, {"source": node.cfg.source},
                   supervisor=node.supervisor)


def _preview(args: argparse.Namespace) -> None:
    from layerpilot.eval.pictures.depth_preview import write_preview

    res = write_preview(args.out, *args.size, index=args.pair, seed=args.seed)
    print(f"wrote {args.out}: precision {res['precision']:.3f}, coverage {res['coverage']:.3f}, "
          f"median |rel err| {res['median_rel_error']:.4f}")

