"""Map commands: `layerpilot map info|scan`."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("map", help="voxel map files and tools")
    sub = p.add_subparsers(dest="map_command", required=True, metavar="ACTION")
    info = sub.add_parser("info", help="print statistics of a .ot/.bt map")
    info.add_argument("path", type=Path)
    info.set_defaults(func=_info)
    scan = sub.add_parser("scan", help="build a map from a plain-text x y z scan and write .ot, .bt and layer pictures")
    scan.add_argument("scan", type=Path, help="text or .bz2 file, one 'x y z' point per line, sensor at the origin")
    scan.add_argument("--out", type=Path, default=Path("runs/scan"))
    scan.add_argument("--resolution", type=float, default=0.2)
    scan.set_defaults(func=_scan)


def _info(args: argparse.Namespace) -> None:
    from layerpilot.map import VoxelMap

    for key, value in VoxelMap.load(args.path).stats().items():
        print(f"{key:>20}: {value}")


def _scan(args: argparse.Namespace) -> None:
    from layerpilot.eval.pictures.scan import build_scan_map

    for path in build_scan_map(args.scan, args.out, args.resolution):
        print(f"wrote {path}")
