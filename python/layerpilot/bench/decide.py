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

from layerpilot.decide.behavior import Behavior
from layerpilot.grid import GridGeometry, GridWindow
from layerpilot.layers.feature_layers import FeatureLayers
from layerpilot.map.columns import ColumnLayers

TARGETS_MS = {512: 5.0, 1024: 10.0}  # issue 18: layers + decision per tick


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


def camera_update(cols: ColumnLayers, rng: np.random.Generator, near: tuple[float, float], now: float,
                  radius: float = 30.0) -> None:
    """One camera footprint of map updates within 60 m of ``near``: columns seen now, a few holes flipping."""
    g = cols.geometry
    cx, cy = near[0] + rng.uniform(-60, 60), near[1] + rng.uniform(-60, 60)
    window = GridWindow.around(g, cx, cy, radius)
    x = g.origin_x + (np.arange(window.col0, window.col1) + 0.5) * g.resolution
    y = g.origin_y + (np.arange(window.row0, window.row1) + 0.5) * g.resolution
    disc = np.hypot(x[None, :] - cx, y[:, None] - cy) < radius
    seen = disc & (rng.random(disc.shape) > 0.03)
    lost = disc & ~seen
    for name, value in (("observed", True), ("last_seen", now), ("min_distance", np.float32(rng.uniform(20, 60)))):
        getattr(cols, name)[window.slices][seen] = value
    cols.elevation[window.slices][seen] = np.float32(rng.uniform(0, 20))
    cols.observed[window.slices][lost] = False
    cols.last_seen[window.slices][lost] = np.nan
    cols.elevation[window.slices][lost] = np.nan
    cols.min_distance[window.slices][lost] = np.inf


def _tick_times(tick: Callable[[], object], update: Callable[[], None], repeat: int) -> tuple[float, float, float]:
    """Median and 90th percentile (ms) of ``tick``, with an untimed ``update`` of the map before each,
    and the median of the process's CPU time per tick (what other work on the cores inflates least)."""
    samples, cpu = [], []
    for _ in range(repeat + 1):
        update()
        t0, c0 = time.perf_counter(), time.process_time()
        tick()
        samples.append(1000 * (time.perf_counter() - t0))
        cpu.append(1000 * (time.process_time() - c0))
    return float(np.median(samples[1:])), float(np.percentile(samples[1:], 90)), float(np.median(cpu[1:]))


def run_decide_bench(sizes: list[int], repeat: int = 30, behavior_name: str = "balanced") -> dict:
    """Per grid size: ``time_ticks`` on a synthetic survey (see there) of that many cells a side."""
    from layerpilot.decide import load_behavior

    for size in sizes:
        if size < 32:
            raise ValueError(f"sizes: each size must be >= 32, got {size}")
    if repeat < 1:
        raise ValueError(f"repeat: must be >= 1, got {repeat}")
    base = load_behavior(behavior_name)
    results = {}
    for size in sizes:
        row = time_ticks(synthetic_columns(size), base, repeat, seed=size)
        if size in TARGETS_MS:
            row["target_ms"] = TARGETS_MS[size]
            row["meets_target"] = row["total_ms"] < TARGETS_MS[size]
        results[str(size)] = row
    return {
        "bench": "decide",
        "behavior": base.name,
        "r_i": base.r_i,
        "layers": base.layer_names,
        "repeat": repeat,
        "sizes": results,
        "meets_targets": all(r.get("meets_target", True) for r in results.values()),
        "all_same_decision": all(r["same_decision"] for r in results.values()),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}, "
                   f"numpy {np.__version__}, opencv {cv2.__version__}, {cv2.getNumThreads()} cv threads",
    }


def time_ticks(cols: ColumnLayers, base: Behavior, repeat: int, seed: int = 0) -> dict:
    """One decision tick as the pilot runs it (layers on the maker's window, the fringe's
    distances redone where the map changed, then the decision) beside one bare whole-grid
    OpenCV distance transform.

    Each timed tick follows an untimed camera footprint of map updates near the drone (what
    changes between two real ticks; ``cols`` is changed in place); "static" ticks see no
    change. The behavior's area of interest is widened to cover the grid (a survey of that
    size); r_i stays the behavior's. Three untimed ticks first are checked against
    whole-grid decisions on the same maps.
    """
    import dataclasses

    from layerpilot.decide import DecisionMaker
    from layerpilot.layers import LayerContext, compute_layers

    g = cols.geometry
    centre = g.cell_center(g.height // 2, g.width // 2)
    area = dataclasses.replace(base.area, radius=0.45 * min(g.width, g.height) * g.resolution, center=centre)
    behavior = dataclasses.replace(base, area=area)
    names = behavior.layer_names
    rng = np.random.default_rng(seed)
    maker, whole = DecisionMaker(behavior, centre), DecisionMaker(behavior, centre)
    clock = {"now": 600.0, "position": (centre[0] + 3.0, centre[1] - 2.0, 50.0), "same": True}

    def context() -> LayerContext:
        return LayerContext(now=clock["now"], options=behavior.layers)

    def update() -> None:
        clock["now"] += 5.0
        camera_update(cols, rng, clock["position"][:2], clock["now"])

    parts: dict[str, list[float]] = {name: [] for name in [*names, "decision"]}

    def tick() -> object:
        """The pilot's tick, its layers one by one so that each one's share is timed too."""
        position, ctx = clock["position"], context()
        window, layers = maker.window(g, position), {}
        for name in names:
            t0 = time.perf_counter()
            layers[name] = compute_layers(cols, ctx, [name], window=window)[name]
            parts[name].append(1000 * (time.perf_counter() - t0))
        t0 = time.perf_counter()
        decision = maker.decide(FeatureLayers(g, layers, cols.observed, cols.elevation, cols.color, ctx.now, window),
                                position, clock["now"], widen=lambda w: compute_layers(cols, ctx, names, window=w))
        parts["decision"].append(1000 * (time.perf_counter() - t0))
        clock["position"] = decision.waypoint
        return decision

    for _ in range(3):  # untimed: the windowed ticks choose what whole-grid ticks choose
        update()
        position, ctx = clock["position"], context()
        want = whole.decide(compute_layers(cols, ctx, names), position, clock["now"])
        clock["same"] &= tick() == want
    row: dict = {}
    for part in parts.values():
        part.clear()
    row["total_ms"], row["total_p90_ms"], row["total_cpu_ms"] = _tick_times(tick, update, repeat)
    for name, part in parts.items():  # the first (warm-up) tick is left out, as in _tick_times
        row[f"layer_{name}_ms" if name != "decision" else "decision_ms"] = float(np.median(part[1:]))
    row["static_total_ms"] = _tick_times(tick, lambda: None, repeat)[0]
    row["window_cells"] = list(maker.window(g, clock["position"]).shape)
    row["same_decision"] = bool(clock["same"])
    mask = np.ascontiguousarray(cols.observed).view(np.uint8)
    row["reference_distance_transform_ms"] = _time(
        lambda: cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE), repeat)[0]
    row["ratio_to_reference"] = row["total_ms"] / row["reference_distance_transform_ms"]
    return row


def print_decide_bench(result: dict) -> None:
    """A table for people, then the result as one JSON line (last line of output)."""
    names = result["layers"]
    head = ["grid", "window", *[f"{n} ms" for n in names], "decision ms", "tick ms", "tick p90", "tick cpu",
            "static ms",
            "cv2 DT ms", "ratio", "same"]
    print(f"bench decide: behavior {result['behavior']} (r_i {result['r_i']:.0f} m, area widened to the grid), "
          f"a camera footprint of map updates before each tick, median of {result['repeat']}; {result['machine']}")
    print(" | ".join(f"{h:>11}" for h in head))
    for size, row in result["sizes"].items():
        cells = [f"{size}x{size}", "x".join(map(str, row["window_cells"])),
                 *[f"{row[f'layer_{n}_ms']:.2f}" for n in names], f"{row['decision_ms']:.2f}", f"{row['total_ms']:.2f}",
                 f"{row['total_p90_ms']:.2f}", f"{row['total_cpu_ms']:.2f}", f"{row['static_total_ms']:.2f}",
                 f"{row['reference_distance_transform_ms']:.2f}", f"{row['ratio_to_reference']:.2f}x",
                 "yes" if row["same_decision"] else "NO"]
        print(" | ".join(f"{c:>11}" for c in cells))
    for size, row in result["sizes"].items():
        if "target_ms" in row:
            verdict = "meets" if row["meets_target"] else "MISSES"
            print(f"{size}x{size}: tick {row['total_ms']:.2f} ms {verdict} the {row['target_ms']:.0f} ms target")
    print(json.dumps(result))
