"""`layerpilot bench decide`: time the layers and the decision on big grids.

The reference in the same run is one bare OpenCV distance transform of the grid (the
single most expensive primitive the fringe needs): the ratio says how many of those a
whole decision costs.
"""

from __future__ import annotations

import json
import os
import platform
import time
from collections.abc import Callable

import cv2
import numpy as np

from layerpilot.grid import GridGeometry
from layerpilot.map.columns import ColumnLayers

TARGET_MS = 10.0


def synthetic_columns(size: int, seed: int = 0, now: float = 600.0) -> ColumnLayers:
    """A plausible map window: a blobby observed region with holes, ages and view distances."""
    rng = np.random.default_rng(seed)
    g = GridGeometry.centered(0.0, 0.0, 1.0, size, size)
    small = rng.random((size // 16 + 1, size // 16 + 1)).astype(np.float32)
    field = cv2.resize(small, (size, size), interpolation=cv2.INTER_CUBIC)
    x, y = g.cell_centers()
    radial = np.hypot(x, y) / (0.5 * size)
    observed = (field - radial > -0.2) & (rng.random(g.shape) > 0.03)
    cols = ColumnLayers.empty(g)
    cols.observed[:] = observed
    cols.elevation[observed] = (field[observed] * 20).astype(np.float32)
    cols.last_seen[observed] = now * field[observed]
    cols.min_distance[observed] = (10 + 140 * rng.random(int(observed.sum()))).astype(np.float32)
    cols.color[observed] = 120
    return cols


def _time(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Median and 90th percentile in milliseconds (after one warm-up call)."""
    fn()
    samples = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        samples.append(1000 * (time.perf_counter() - t0))
    return float(np.median(samples)), float(np.percentile(samples, 90))


def run_decide_bench(sizes: list[int], repeat: int = 30, behavior_name: str = "balanced") -> dict:
    from layerpilot.decide import DecisionMaker, load_behavior
    from layerpilot.layers import LayerContext, compute_layers

    for size in sizes:
        if size < 32:
            raise ValueError(f"sizes: each size must be >= 32, got {size}")
    if repeat < 1:
        raise ValueError(f"repeat: must be >= 1, got {repeat}")
    behavior = load_behavior(behavior_name)
    names = behavior.layer_names
    results = {}
    for size in sizes:
        cols = synthetic_columns(size)
        ctx = LayerContext(now=600.0, options=behavior.layers)
        layers = compute_layers(cols, ctx, names)
        dm = DecisionMaker(behavior)
        t = iter(range(10**9))
        row = {}
        for name in names:
            row[f"layer_{name}_ms"] = _time(lambda: compute_layers(cols, ctx, [name]), repeat)[0]
        row["layers_ms"], row["layers_p90_ms"] = _time(lambda: compute_layers(cols, ctx, names), repeat)
        row["decide_ms"], row["decide_p90_ms"] = _time(lambda: dm.decide(layers, (3.0, -2.0, 50.0), float(next(t))), repeat)

        def total() -> None:
            dm.decide(compute_layers(cols, ctx, names), (3.0, -2.0, 50.0), float(next(t)))

        row["total_ms"], row["total_p90_ms"] = _time(total, repeat)
        mask = cols.observed.view(np.uint8)
        row["reference_distance_transform_ms"] = _time(
            lambda: cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE), repeat)[0]
        row["ratio_to_reference"] = row["total_ms"] / row["reference_distance_transform_ms"]
        results[str(size)] = row
    first = results[str(sizes[0])]
    return {
        "bench": "decide",
        "behavior": behavior.name,
        "layers": names,
        "repeat": repeat,
        "sizes": results,
        "target_ms": TARGET_MS,
        "target_size": 512,
        "meets_target": results["512"]["total_ms"] < TARGET_MS if "512" in results else None,
        "first_size_total_ms": first["total_ms"],
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
                   f"numpy {np.__version__}, opencv {cv2.__version__}, {cv2.getNumThreads()} cv threads",
    }


def print_decide_bench(result: dict) -> None:
    """A table for people, then the result as one JSON line (last line of output)."""
    names = result["layers"]
    head = ["grid", *[f"{n} ms" for n in names], "layers ms", "decide ms", "total ms", "total p90", "cv2 DT ms", "ratio"]
    print(f"bench decide: behavior {result['behavior']}, median of {result['repeat']}; {result['machine']}")
    print(" | ".join(f"{h:>10}" for h in head))
    for size, row in result["sizes"].items():
        cells = [f"{size}x{size}", *[f"{row[f'layer_{n}_ms']:.2f}" for n in names], f"{row['layers_ms']:.2f}",
                 f"{row['decide_ms']:.2f}", f"{row['total_ms']:.2f}", f"{row['total_p90_ms']:.2f}",
                 f"{row['reference_distance_transform_ms']:.2f}", f"{row['ratio_to_reference']:.1f}x"]
        print(" | ".join(f"{c:>10}" for c in cells))
    if result["meets_target"] is not None:
        verdict = "meets" if result["meets_target"] else "MISSES"
        print(f"512x512 total {result['sizes']['512']['total_ms']:.2f} ms {verdict} the {result['target_ms']:.0f} ms target")
    print(json.dumps(result))
