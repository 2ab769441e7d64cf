"""`layerpilot bench scale`: each cost of a survey as its area grows, in one run on one machine.

For each square area side (100 m to 1 km by default): a lawnmower survey of a world that
wide (ground-truth depth of 320x240 frames from 50 m, as `bench map`'s memory run) into the
map at 1 m, then on the window covering the area plus a 20 m margin:

- insertion: ms per survey frame, and the map's memory (whole map, bytes per leaf);
- layer query: what the map server does when the map has changed since the last ask
  (column extraction, encoding) and what the reader does (decoding), with the bytes;
- decision: one pilot tick on the surveyed columns (``bench.decide.time_ticks``: a camera
  footprint of map updates before each, and static), and the bare OpenCV distance
  transform of the window as the reference.

A table is printed, then the result as one JSON line (last line).
"""

from __future__ import annotations

import json
import os
import platform
import time

import cv2
import numpy as np

from layerpilot.bench.decide import time_ticks
from layerpilot.bus.layerset import decode_layer_set, encode_columns, to_column_layers
from layerpilot.decide import load_behavior
from layerpilot.map import VoxelMap
from layerpilot.progress import Progress

MARGIN = 20.0  # m of window past the area on every side, as decide.area_geometry


def _median_ms(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(1000 * (time.perf_counter() - t))
    return float(np.median(times))


def run_scale_bench(sides: list[float], repeat: int = 15, seed: int = 0) -> dict:
    from layerpilot.eval.fixtures import area_survey_clouds  # renders with OpenGL

    for side in sides:
        if not 50 <= side <= 2000:
            raise ValueError(f"sides: each side must be within [50, 2000] m, got {side}")
    behavior = load_behavior("balanced")
    rows = {}
    for side in sides:
        voxel_map, frames, insert_ms, bar = VoxelMap(1.0), 0, 0.0, None
        for count, f in area_survey_clouds(side, seed):
            bar = bar or Progress(count, f"bench scale, {side:.0f} m survey", " frames")
            t = time.perf_counter()
            voxel_map.insert(f.points, f.origin, f.colors, f.stamp, 100.0)
            insert_ms += 1000 * (time.perf_counter() - t)
            frames += 1
            bar.update(frames)
        stats = voxel_map.stats()
        cells = int(np.ceil(side + 2 * MARGIN))
        corner = -side / 2 - MARGIN
        columns = voxel_map.column_layers(corner, corner, cells, cells)
        row: dict = {"frames": frames, "insert_ms_per_frame": insert_ms / frames,
                     "memory_mib": stats["total_bytes"] / 2**20, "bytes_per_leaf": stats["bytes_per_leaf"],
                     "leaves": stats["leaves"], "window_cells": cells,
                     "observed_fraction": float(columns.observed.mean())}
        row["columns_ms"] = _median_ms(lambda: voxel_map.column_layers(corner, corner, cells, cells), repeat)
        try:
            payload = encode_columns(columns, 0.0, "bench")
            row["layer_set_bytes"] = len(payload)
            row["encode_ms"] = _median_ms(lambda: encode_columns(columns, 0.0, "bench"), repeat)
            row["decode_ms"] = _median_ms(lambda: to_column_layers(decode_layer_set(payload)), repeat)
        except ValueError as exc:  # more than a layer set may carry: say so in the table
            row["layer_set_error"] = str(exc)
        tick = time_ticks(columns, behavior, repeat, seed)
        row.update({k: tick[k] for k in ("total_ms", "total_p90_ms", "static_total_ms", "same_decision",
                                         "reference_distance_transform_ms", "ratio_to_reference")})
        rows[f"{side:g}"] = row
    return {
        "bench": "scale",
        "repeat": repeat,
        "sides_m": rows,
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}, "
                   f"numpy {np.__version__}, opencv {cv2.__version__}",
    }


def print_scale_bench(result: dict) -> None:
    head = ["area", "frames", "insert ms", "memory MiB", "B/leaf", "window", "observed", "columns ms",
            "encode ms", "decode ms", "set bytes", "tick ms", "static ms", "cv2 DT ms", "same"]
    print(f"bench scale: median of {result['repeat']}; {result['machine']}")
    print(" | ".join(f"{h:>10}" for h in head))
    for side, r in result["sides_m"].items():
        query = ([f"{r['encode_ms']:.2f}", f"{r['decode_ms']:.2f}", str(r["layer_set_bytes"])]
                 if "encode_ms" in r else ["refused", "-", "-"])
        cells = [f"{side} m", str(r["frames"]), f"{r['insert_ms_per_frame']:.1f}", f"{r['memory_mib']:.1f}",
                 f"{r['bytes_per_leaf']:.1f}", f"{r['window_cells']}^2", f"{100 * r['observed_fraction']:.0f}%",
                 f"{r['columns_ms']:.2f}", *query, f"{r['total_ms']:.2f}", f"{r['static_total_ms']:.2f}",
                 f"{r['reference_distance_transform_ms']:.2f}", "yes" if r["same_decision"] else "NO"]
        print(" | ".join(f"{c:>10}" for c in cells))
        if "layer_set_error" in r:
            print(f"  {side} m layer set: {r['layer_set_error']}")
    print(json.dumps(result))
