"""`layerpilot bench map`: layerpilot's insertion side by side with stock OctoMap, same frames, same run;
then both maps' memory after a lawnmower survey of a whole simulated world (a square kilometre)."""

from __future__ import annotations

import json
import time

import numpy as np

from layerpilot.bench._octomap import OcTree
from layerpilot.map.voxel_map import KEY_OFFSET, VoxelMap
from layerpilot.progress import Progress


def _ms(f) -> float:
    t0 = time.perf_counter()
    f()
    return 1000 * (time.perf_counter() - t0)


def voxel_keys(centers: np.ndarray, resolution: float) -> np.ndarray:
    """One int64 per voxel centre: its OctoMap key, x | y << 16 | z << 32."""
    k = np.floor(centers.astype(np.float64) / resolution).astype(np.int64) + KEY_OFFSET
    return k[:, 0] | (k[:, 1] << 16) | (k[:, 2] << 32)


def all_voxels(m: VoxelMap) -> tuple[np.ndarray, np.ndarray]:
    """Every finest-level voxel the map knows: centres (n, 3) and occupancy probability."""
    s = m.stats()
    v = m.voxels(np.array(s["bounds_min"]), np.array(s["bounds_max"]), min_occupancy=0.0)
    return v.centers, v.occupancy


def compare_voxels(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray], resolution: float) -> dict:
    """Two maps' voxels (``all_voxels`` or ``OcTree.voxels``) voxel by voxel: how many either
    knows, and how many both know with the very same occupancy (the same log-odds)."""
    keys_a, keys_b = voxel_keys(a[0], resolution), voxel_keys(b[0], resolution)
    both, ia, ib = np.intersect1d(keys_a, keys_b, assume_unique=True, return_indices=True)
    return {"voxels": len(keys_a) + len(keys_b) - len(both), "identical": int(np.sum(a[1][ia] == b[1][ib]))}


def run_map_bench(frames: list, resolution: float = 1.0, max_range: float = 100.0) -> dict:
    """Insert ``frames`` with layerpilot and with OctoMap (discretized and default), each into a
    map of its own, and compare mean milliseconds per frame over the same frames."""
    ours, discretized, default = VoxelMap(resolution), OcTree(resolution), OcTree(resolution)
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
    same = compare_voxels(all_voxels(ours), discretized.voxels(), resolution)
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
        "voxels_identical": same["identical"],  # same log-odds as OctoMap discretized
        "voxels_compared": same["voxels"],
        "column_layers_512_ms": round(window, 2),
        "node_bytes": stats["node_bytes"],
        "bytes_per_leaf": round(stats["bytes_per_leaf"], 1),
        "octomap_bytes_per_leaf": round(discretized.memory_usage() / discretized.leaves(), 1),
        "leaves": stats["leaves"],
    }


def run_memory_bench(world_size: float, seed: int = 0, resolution: float = 1.0, max_range: float = 100.0) -> dict:
    """Survey a whole ``world_size`` world (``area_survey_clouds``) into layerpilot's map and into
    stock OctoMap (discretized insertion, occupancy only), and compare their memory.

    layerpilot's figure is the whole map (``VoxelMap.stats``: tree, attribute records, column
    index); the largest working memory of one insert is reported beside it. OctoMap's is its
    own ``memoryUsage()`` (nodes and child arrays, no allocator overhead, no insertion sets).
    """
    from layerpilot.eval.fixtures import area_survey_clouds  # renders with OpenGL

    ours, stock = VoxelMap(resolution), OcTree(resolution)
    bar, points, frames, ms_ours, ms_stock = None, 0, 0, 0.0, 0.0
    for count, f in area_survey_clouds(world_size, seed, max_depth=max_range):
        bar = bar or Progress(count, f"bench map memory, {world_size:.0f} m world", " frames")
        ms_ours += _ms(lambda: ours.insert(f.points, f.origin, f.colors, f.stamp, max_range))
        ms_stock += stock.insert(f.points[np.isfinite(f.points).all(axis=1)], f.origin, max_range, True)
        frames, points = frames + 1, points + len(f.points)
        bar.update(frames, f"{len(f.points)} points")
    s = ours.stats()
    mib = 1 / 2**20
    return {
        "world_size_m": world_size,
        "survey_frames": frames,
        "survey_points": points,
        "leaves": s["leaves"],
        "octomap_leaves": stock.leaves(),
        "attribute_records": s["attribute_records"],
        "tree_mib": round(s["tree_bytes"] * mib, 2),
        "column_index_mib": round(s["column_index_bytes"] * mib, 2),
        "total_mib": round(s["total_bytes"] * mib, 2),
        "insert_scratch_mib": round(s["insert_scratch_bytes"] * mib, 2),
        "octomap_mib": round(stock.memory_usage() * mib, 2),
        "bytes_per_leaf": round(s["bytes_per_leaf"], 2),
        "bytes_per_leaf_with_insert_scratch": round((s["total_bytes"] + s["insert_scratch_bytes"]) / s["leaves"], 2),
        "octomap_bytes_per_leaf": round(stock.memory_usage() / stock.leaves(), 2),
        "ratio_memory": round(stock.memory_usage() / s["total_bytes"], 2),
        "survey_insert_ms_per_frame": round(ms_ours / frames, 2),
        "octomap_survey_insert_ms_per_frame": round(ms_stock / frames, 2),
    }


def print_memory_bench(m: dict) -> None:
    rows = [
        ("survey", f"{m['survey_frames']} frames of 320x240, {m['survey_points']} points, "
                   f"{m['world_size_m']:.0f} m x {m['world_size_m']:.0f} m world"),
        ("layerpilot whole map (all attributes)", f"{m['total_mib']:.1f} MiB = {m['bytes_per_leaf']:.2f} B/leaf "
                                                  f"over {m['leaves']} leaves"),
        ("  tree (8-byte nodes, 64-byte groups)", f"{m['tree_mib']:.1f} MiB, {m['attribute_records']} attribute records"),
        ("  column index", f"{m['column_index_mib']:.1f} MiB"),
        ("  largest insert working memory", f"{m['insert_scratch_mib']:.1f} MiB (freed after each insert; "
                                            f"{m['bytes_per_leaf_with_insert_scratch']:.2f} B/leaf counted in)"),
        ("OctoMap OcTree memoryUsage (occupancy only)", f"{m['octomap_mib']:.1f} MiB = "
                                                        f"{m['octomap_bytes_per_leaf']:.2f} B/leaf over {m['octomap_leaves']} leaves"),
        ("OctoMap / layerpilot memory", f"{m['ratio_memory']:.2f}x"),
        ("insert on the survey, ms/frame", f"{m['survey_insert_ms_per_frame']:.1f} "
                                           f"(OctoMap discretized {m['octomap_survey_insert_ms_per_frame']:.1f})"),
    ]
    width = max(len(name) for name, _ in rows)
    for name, value in rows:
        print(f"  {name:<{width}}  {value}")


def print_map_bench(result: dict) -> None:
    rows = [
        ("layerpilot insert", f"{result['layerpilot_ms']:.1f} ms/frame"),
        ("OctoMap insertPointCloud discretized", f"{result['octomap_discretized_ms']:.1f} ms/frame"),
        ("OctoMap insertPointCloud default", f"{result['octomap_default_ms']:.1f} ms/frame"),
        ("speed-up vs discretized", f"{result['ratio_vs_discretized']:.1f}x"),
        ("speed-up vs default", f"{result['ratio_vs_default']:.1f}x"),
        ("voxels with OctoMap discretized's log-odds", f"{result['voxels_identical']} of {result['voxels_compared']}"),
        ("column layers 512x512", f"{result['column_layers_512_ms']:.2f} ms"),
        ("node size / whole map bytes per leaf", f"{result['node_bytes']} B / {result['bytes_per_leaf']} B"),
        ("OctoMap OcTree bytes per leaf (same data)", f"{result['octomap_bytes_per_leaf']} B"),
    ]
    width = max(len(name) for name, _ in rows)
    print(f"{result['frames']} frames of {result['points_per_frame']} points, 1 m voxels, 100 m range")
    for name, value in rows:
        print(f"  {name:<{width}}  {value}")
    if "memory" in result:
        print_memory_bench(result["memory"])
    print(json.dumps(result))


def main(frames: int, seed: int, world_size: float) -> None:
    print(f"rendering {frames} simulator frames (640x480, 40-60 m above the forest, pitched 60 deg down)...",
          flush=True)
    from layerpilot.eval.fixtures import survey_clouds  # 640x480 ground-truth depth, far points kept

    result = run_map_bench(survey_clouds(frames, seed))
    if world_size > 0:
        result["memory"] = run_memory_bench(world_size, seed)
    print_map_bench(result)
