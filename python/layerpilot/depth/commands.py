"""Depth commands: `layerpilot depth` (the depth node), `layerpilot depth preview`, `layerpilot bench depth`."""

from __future__ import annotations

import argparse
from pathlib import Path

from layerpilot.nodes.commands import add_node_command


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"size {text!r}: at least 16x16")
    return w, h


def register(commands: argparse._SubParsersAction, benches: argparse._SubParsersAction) -> None:
    p = add_node_command(commands, "depth", "depth from the moving camera: the depth node (camera frames in, "
                         "point clouds out), or an action (preview)")
    sub = p.add_subparsers(dest="depth_command", metavar="ACTION")
    prev = sub.add_parser("preview", help="PNG panel of one rendered pair: rectified views, disparity, depth, error")
    prev.add_argument("--out", type=Path, default=Path("runs/depth_preview.png"))
    prev.add_argument("--size", type=_size, default=(640, 480), help="WIDTHxHEIGHT (default 640x480)")
    prev.add_argument("--pair", type=int, default=0, help="index into the bench's fixed pair set")
    prev.add_argument("--seed", type=int, default=0, help="world seed")
    prev.set_defaults(func=_preview)

    b = benches.add_parser("depth", help="stereo precision, coverage, error and pairs/s on rendered pairs")
    b.add_argument("--sizes", type=lambda t: [_size(s) for s in t.split(",")], default=[(640, 480), (320, 240)])
    b.add_argument("--repeats", type=int, default=3)
    b.add_argument("--seed", type=int, default=0)
    b.set_defaults(func=_bench)


def _preview(args: argparse.Namespace) -> None:
    from layerpilot.depth.preview import write_preview

    res = write_preview(args.out, *args.size, index=args.pair, seed=args.seed)
    print(f"wrote {args.out}: precision {res['precision']:.3f}, coverage {res['coverage']:.3f}, "
          f"median |rel err| {res['median_rel_error']:.4f}")


def _bench(args: argparse.Namespace) -> None:
    from layerpilot.depth.bench import main

    if args.repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {args.repeats}")
    main(args.sizes, args.repeats, args.seed)
