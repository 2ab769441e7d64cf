"""Layer and decision commands: `layerpilot layers render|list|export`."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("layers", help="feature layers and decisions: pictures, registered layers")
    sub = p.add_subparsers(dest="layers_command", required=True, metavar="ACTION")
    r = sub.add_parser("render", help="PNGs of every layer and of A0..A3 with the chosen waypoint")
    r.add_argument("--map", type=Path, help=".ot/.bt map (default: a synthetic survey map built on the spot)")
    r.add_argument("--behavior", default="balanced", help="preset name or .toml file (default: balanced)")
    r.add_argument("--position", type=float, nargs=3, metavar=("X", "Y", "Z"), help="drone position, map frame")
    r.add_argument("--home", type=float, nargs=2, default=(0.0, 0.0), metavar=("X", "Y"), help="launch point")
    r.add_argument("--now", type=float, help="mission time (default: the newest observation in the window)")
    r.add_argument("--frames", type=int, default=6, help="synthetic map: frames to insert")
    r.add_argument("--out", type=Path, default=Path("runs/layers"))
    r.set_defaults(func=_render)
    ls = sub.add_parser("list", help="registered layer names (after importing a behavior's plugins)")
    ls.add_argument("--behavior", help="also load this behavior's plugins")
    ls.set_defaults(func=_list)
    ex = sub.add_parser("export", help="GeoTIFFs of the color, elevation and decision layers of a run's map (for QGIS)")
    ex.add_argument("run", type=Path, help="run directory (its map.ot or map.bt) or a .ot/.bt map file")
    ex.add_argument("--origin", type=float, nargs=3, metavar=("LAT", "LON", "ALT"),
                    help="the map frame's geodetic origin (default: the run directory's frame.json)")
    ex.add_argument("--layer", action="append", dest="layers", metavar="NAME",
                    help="decision layer to export (repeatable; default: fringe, time, distance, elevation; "
                         "only layers a map alone gives, not view_gain)")
    ex.add_argument("--out", type=Path, help="output folder (default: <run directory>/geotiff)")
    ex.set_defaults(func=_export)


def _render(args: argparse.Namespace) -> None:
    from layerpilot.eval.pictures.scene import render_scene

    for path in render_scene(args.behavior, args.out, map_path=args.map, position=args.position,
                             home=tuple(args.home), now=args.now, frames=args.frames):
        print(f"wrote {path}")


def _list(args: argparse.Namespace) -> None:
    from layerpilot.layers import layer_names

    if args.behavior:
        from layerpilot.decide import load_behavior

        load_behavior(args.behavior)
    print("\n".join(layer_names()))


def _export(args: argparse.Namespace) -> None:
    from layerpilot.eval.geotiff import MAP_LAYERS, export_layers
    from layerpilot.eval.run_frame import read_run_frame, run_map_path
    from layerpilot.map import VoxelMap

    map_path, run_dir = run_map_path(args.run)
    frame = read_run_frame(run_dir, args.origin)
    out = args.out or (run_dir or map_path.parent) / "geotiff"
    for path in export_layers(VoxelMap.load(map_path), frame, out, args.layers or MAP_LAYERS):
        print(f"wrote {path}")
    print(f"CRS: {frame.crs.name} (transverse Mercator on WGS 84; UTM zone EPSG:{frame.utm_crs.to_epsg()})")
