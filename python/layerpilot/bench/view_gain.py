"""`layerpilot bench view`: the view_gain layer's cost per decision tick, beside two references.

References in the same run, on the same synthetic map window: the ``fringe`` layer (the
frontier layer view_gain stands in for) and one bare full-resolution OpenCV correlation of
the grid with the camera's footprint (what the layer would cost done naively, without its
2 m working grid, occlusion bands or heading sectors).
"""

from __future__ import annotations

import json
import math
import os
import platform

import cv2
import numpy as np

from layerpilot.bench.decide import _time, synthetic_columns
from layerpilot.layers import LayerContext, compute_layers
from layerpilot.layers.view_gain import CameraView, footprint

VFOV_320x240 = math.degrees(2 * math.atan(240 / 320))  # hfov 90 deg, square pixels


def run_view_bench(sizes: list[int], repeat: int = 10) -> dict:
    """Median ms of view_gain (fixed heading: one footprint; side: one per heading sector) and the references."""
    for size in sizes:
        if size < 64:
            raise ValueError(f"sizes: each size must be >= 64, got {size}")
    if repeat < 1:
        raise ValueError(f"repeat: must be >= 1, got {repeat}")
    results = {}
    for size in sizes:
        cols = synthetic_columns(size)
        aoi = np.ones(cols.geometry.shape, bool)
        row = {}
        for heading in ("fixed", "side"):
            view = CameraView(50.0, 60.0, 90.0, VFOV_320x240, 100.0, heading=heading, yaw=math.pi / 2)
            ctx = LayerContext(now=600.0, position=(3.0, -2.0, 50.0), view=view, aoi=aoi)
            row[f"view_gain_{heading}_ms"] = _time(lambda: compute_layers(cols, ctx, ["view_gain"]), repeat)[0]
        ctx = LayerContext(now=600.0)
        row["reference_fringe_ms"] = _time(lambda: compute_layers(cols, ctx, ["fringe"]), repeat)[0]
        kernel, _ = footprint(CameraView(50.0, 60.0, 90.0, VFOV_320x240, 100.0), math.pi / 2, 1.0)
        weights = (~cols.observed).astype(np.float32)
        row["reference_full_res_correlation_ms"] = _time(
            lambda: cv2.filter2D(weights, cv2.CV_32F, kernel, borderType=cv2.BORDER_CONSTANT), repeat)[0]
        row["fixed_over_correlation"] = row["view_gain_fixed_ms"] / row["reference_full_res_correlation_ms"]
        results[str(size)] = row
    return {
        "bench": "view",
        "repeat": repeat,
        "sizes": results,
        "camera": "320x240, hfov 90 deg, pitch 60 deg, 50 m up, 100 m range",
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
                   f"numpy {np.__version__}, opencv {cv2.__version__}, {cv2.getNumThreads()} cv threads",
    }


def print_view_bench(result: dict) -> None:
    """A table for people, then the result as one JSON line (last line of output)."""
    head = ["grid", "view fixed ms", "view side ms", "fringe ms", "full-res corr ms", "fixed/corr"]
    print(f"bench view: median of {result['repeat']}; {result['camera']}; {result['machine']}")
    print(" | ".join(f"{h:>16}" for h in head))
    for size, row in result["sizes"].items():
        cells = [f"{size}x{size}", f"{row['view_gain_fixed_ms']:.1f}", f"{row['view_gain_side_ms']:.1f}",
                 f"{row['reference_fringe_ms']:.1f}", f"{row['reference_full_res_correlation_ms']:.1f}",
                 f"{row['fixed_over_correlation']:.2f}x"]
        print(" | ".join(f"{c:>16}" for c in cells))
    print(json.dumps(result))
