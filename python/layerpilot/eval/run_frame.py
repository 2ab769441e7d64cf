"""Where a run directory's map lies on the Earth, and which map file it holds.

A run directory that knows its place carries ``frame.json``: the geodetic origin of its map
frame, ``{"lat": deg, "lon": deg, "alt": m}``. `layerpilot map images` writes it from the first
photo; for a simulated mission the map frame's origin is the autopilot's EKF origin (home, on the
ground: ``MavlinkVehicle.ekf_frame``), which the lock-step evaluator writes into its run directory
and the simulator node beside the map server's snapshot. A map without one takes ``--origin LAT LON ALT``.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from pathlib import Path

from layerpilot.geodesy import LocalFrame

FRAME_FILE = "frame.json"


def write_run_frame(run_dir: Path, frame: LocalFrame) -> Path:
    """Written whole (a reader, or another vehicle's simulator node writing the same, never sees half a file)."""
    path = Path(run_dir) / FRAME_FILE
    tmp = path.with_name(f".{FRAME_FILE}.{os.getpid()}")
    tmp.write_text(json.dumps({"lat": frame.lat, "lon": frame.lon, "alt": frame.alt}) + "\n")
    os.replace(tmp, path)
    return path


def read_run_frame(run_dir: Path | None, origin: Sequence[float] | None = None) -> LocalFrame:
    """``origin`` (lat, lon, alt) if given, else the run directory's frame.json; a clear error if neither."""
    if origin is not None:
        return LocalFrame(*(float(v) for v in origin))
    path = None if run_dir is None else Path(run_dir) / FRAME_FILE
    if path is None or not path.is_file():
        raise ValueError(f"{path or 'map'}: no {FRAME_FILE} says where this map lies on the Earth; "
                         "pass --origin LAT LON ALT (the map frame's origin: for a simulated mission, "
                         "the vehicle's home on the ground)")
    try:
        data = json.loads(path.read_text())
        values = [float(data[k]) for k in ("lat", "lon", "alt")]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: expected {{\"lat\": .., \"lon\": .., \"alt\": ..}} in degrees and metres: "
                         f"{exc!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{path}: lat, lon and alt must be finite numbers, got {values}")
    return LocalFrame(*values)


def run_map_path(run_or_map: Path) -> tuple[Path, Path | None]:
    """(map file, run directory or None) for a run directory (its map.ot, else map.bt) or a map file."""
    path = Path(run_or_map)
    if path.is_dir():
        for name in ("map.ot", "map.bt"):
            if (path / name).is_file():
                return path / name, path
        raise FileNotFoundError(f"{path}: a run directory holds map.ot or map.bt; found neither")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such run directory or map file")
    return path, (path.parent if (path.parent / FRAME_FILE).is_file() else None)
