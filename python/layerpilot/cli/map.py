"""Map commands: `layerpilot map info|scan|images`."""

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
    scan.add_argument("--out", type=Path, default=Path("runs/scan"),
                      help="run directory: map.ot, map.bt and the layer pictures (default runs/scan)")
    scan.add_argument("--resolution", type=float, default=0.2, help="voxel size in metres")
    scan.set_defaults(func=_scan)
    images = sub.add_parser("images", help="build the map and layers from a folder of geotagged drone photos")
    images.add_argument("folder", type=Path, help="folder of JPEGs with EXIF GPS and DJI/Parrot XMP attitude, "
                                                  "or a project folder with them in images/")
    images.add_argument("--out", type=Path, default=Path("runs/photos"),
                        help="run directory: map.ot, map.bt, frame.json, cameras.csv, pairs.csv, layer pictures and "
                             "the report (default runs/photos)")
    images.add_argument("--calibration", type=Path, help="OpenCV YAML calibration overriding EXIF intrinsics")
    images.add_argument("--origin", type=float, nargs=3, metavar=("LAT", "LON", "ALT"),
                        help="map frame origin (default: below the first photo at its take-off height)")
    images.add_argument("--width", type=int, default=1000, help="working image width in pixels")
    images.add_argument("--resolution", type=float, default=0.5, help="voxel size in metres")
    images.add_argument("--poses", choices=("adjusted", "refined", "raw"), default="adjusted",
                        help="bundle-adjusted (default), refined per pair, or raw GNSS/attitude poses")
    images.set_defaults(func=_images)


def _info(args: argparse.Namespace) -> None:
    from layerpilot.map import VoxelMap

    for key, value in VoxelMap.load(args.path).stats().items():
        print(f"{key:>20}: {value}")


def _scan(args: argparse.Namespace) -> None:
    from layerpilot.eval.pictures.scan import build_scan_map

    for path in build_scan_map(args.scan, args.out, args.resolution):
        print(f"wrote {path}")


def _images(args: argparse.Namespace) -> None:
    from layerpilot.eval.photo_run import build_photo_map, write_photo_run
    from layerpilot.geodesy import LocalFrame
    from layerpilot.photos import PhotoConfig, read_folder
    from layerpilot.photos.calibration import read_calibration

    config = PhotoConfig(width=args.width, poses=args.poses, resolution=args.resolution)
    folder = read_folder(args.folder, LocalFrame(*args.origin) if args.origin else None,
                         read_calibration(args.calibration) if args.calibration else None, args.width)
    for name, why in folder.skipped.items():
        print(f"skipped {name}: {why}")
    if len(folder.photos) < 2:  # a map needs depth, and depth needs a pair
        raise ValueError(f"{args.folder}: only {len(folder.photos)} usable photo ({folder.photos[0].path.name}): "
                         f"no pair could be made; a map needs at least two overlapping photos")
    result = build_photo_map(folder, config, label="map images")
    for p in result.pairs:
        print(f"pair {folder.photos[p.ref].path.name} + {folder.photos[p.partner].path.name}: {p.reason}"
              + (f", {p.refinement.inliers} inliers, rotation corrected by {p.refinement.rotation_correction_deg:.2f} deg"
                 if p.refinement and p.refinement.inliers else "")
              + (f", {len(p.cloud)} points" if p.cloud is not None else ""))
    if not any(p.cloud is not None for p in result.pairs):
        raise ValueError(f"{args.folder}: none of {len(result.pairs)} photo pairs gave points (reasons above): "
                         f"nothing to map")
    paths = write_photo_run(result, args.out, f"layerpilot map images: {args.folder.name}")
    print(f"wrote {args.out} ({paths['html'] if 'html' in paths else ', '.join(map(str, paths.values()))})")
