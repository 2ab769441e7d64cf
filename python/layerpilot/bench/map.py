"""`layerpilot bench map`: layerpilot's insertion side by side with stock OctoMap, same frames, same run."""

from __future__ import annotations

import json
import time

import numpy as np

from layerpilot import _core
from layerpilot.map.voxel_map import VoxelMap, agreement
from layerpilot.progress import Progress


def _ms(f) -> float:
    t0 = time.perf_counter()
    f()
    return 1000 * (time.perf_counter() - t0)


def run_map_bench(frames: list, resolution: float = 1.0, max_range: float = 100.0) -> dict:
    """Insert ``frames`` with layerpilot and with OctoMap (discretized and default), each into a
    map of its own, and compare mean milliseconds per frame over the same frames."""
    ours, discretized, default = VoxelMap(resolution), _core._ReferenceOcTree(resolution), _core._ReferenceOcTree(resolution)
    finite = [f.points[np.isfinite(f.points).all(axis=1)] for f in frames]  # OctoMap has no NaN handling
    # One pass per implementation over the same frames, so none runs on caches another one left.
    passes = {
        "layerpilot": lambda i, f: _ms(lambda: ours.insert(f.points, f.origin, f.colors, f.stamp, max_range)),
        "OctoMap discretized": lambda i, f: discretized.insert(finite[i], f.origin, max_range, True),
        "OctoMap default": lambda i, f: default.insert(finite[i], f.origin, max_range, False),
    }
    times: dict[str, list[float]] = {}
    bar = Progress(len(frames) * len(passes), "bench map", " inserts")
    for name, insert in passes.items():
        times[name] = []
        for i, f in enumerate(frames):
            times[name].append(insert(i, f))
            bar.update(len(times) * len(frames) - len(frames) + i + 1, f"{name}: {times[name][-1]:.1f} ms")
    t_ours, t_disc, t_default = times.values()
    agree = agreement(ours, discretized)
    stats = ours.stats()
    window = min(_ms(lambda: ours.column_layers(-256, -256, 512, 512)) for _ in range(5))
    ours_ms = float(np.mean(t_ours))
    return {
        "frames": len(frames),
        "points_per_frame": int(np.mean([len(f.points) for f in frames])),
        "layerpilot_ms": round(ours_ms, 2),
        "octomap_discretized_ms": round(float(np.mean(t_disc)), 2),
        "octomap_default_ms": round(float(np.mean(t_default)), 2),
        "ratio_vs_discretized": round(float(np.mean(t_disc)) / ours_ms, 2),
        "ratio_vs_default": round(float(np.mean(t_default)) / ours_ms, 2),
        "voxel_agreement": round(agree["fraction"], 5),
        "voxels_compared": agree["either"],
        "column_layers_512_ms": round(window, 2),
        "node_bytes": stats["node_bytes"],
        "bytes_per_leaf": round(stats["bytes_per_leaf"], 1),
        "octomap_bytes_per_leaf": round(discretized.memory_usage() / discretized.leaves(), 1),
        "leaves": stats["leaves"],
    }


def print_map_bench(result: dict) -> None:
    rows = [
        ("layerpilot insert", f"{result['layerpilot_ms']:.1f} ms/frame"),
        ("OctoMap insertPointCloud discretized", f"{result['octomap_discretized_ms']:.1f} ms/frame"),
        ("OctoMap insertPointCloud default", f"{result['octomap_default_ms']:.1f} ms/frame"),
        ("speed-up vs discretized", f"{result['ratio_vs_discretized']:.1f}x"),
        ("speed-up vs default", f"{result['ratio_vs_default']:.1f}x"),
        ("voxel agreement with discretized", f"{100 * result['voxel_agreement']:.3f} % of {result['voxels_compared']}"),
        ("column layers 512x512", f"{result['column_layers_512_ms']:.2f} ms"),
        ("node size / tree bytes per leaf", f"{result['node_bytes']} B / {result['bytes_per_leaf']} B"),
        ("OctoMap OcTree bytes per leaf (same data)", f"{result['octomap_bytes_per_leaf']} B"),
    ]
    width = max(len(name) for name, _ in rows)
    print(f"{result['frames']} frames of {result['points_per_frame']} points, 1 m voxels, 100 m range")
    for name, value in rows:
        print(f"  {name:<{width}}  {value}")
    print(json.dumps(result))


def main(frames: int, seed: int) -> None:
    print(f"rendering {frames} simulator frames (640x480, 40-60 m above the forest, pitched 60 deg down)...",
          flush=True)
    from layerpilot.eval.fixtures import survey_clouds  # 640x480 ground-truth depth, far points kept

    print_map_bench(run_map_bench(survey_clouds(frames, seed)))
