"""`layerpilot bench depth`: accuracy and speed of stereo depth on a fixed set of rendered pairs.

For each image size the measured preset runs on ``BENCH_PAIRS`` (altitudes 30-60 m,
pitch 45-90 deg, default forest). Accuracy is pooled over all points of all pairs;
speed is wall time of rectification + matching + filtering + reprojection, next to
OpenCV's bare StereoSGBM (one call on the same rectified images) as the reference.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from layerpilot.depth.config import DepthConfig, preset_for
from layerpilot.depth.evaluate import score
from layerpilot.depth.picking import FramePicker
from layerpilot.depth.stereo import StereoMatcher
from layerpilot.eval.fixtures import BENCH_PAIRS, render_pair, terrain_scene_depth


def run_size(world, width: int, height: int, repeats: int) -> dict:
    import dataclasses

    from layerpilot.sim import CameraConfig, Renderer

    config: DepthConfig = preset_for(width)
    with Renderer(world, CameraConfig(width=width, height=height)) as r:
        pairs = [render_pair(r, dataclasses.replace(s, ratio=config.pick.target_baseline_ratio), stamp=1.0)
                 for s in BENCH_PAIRS]
    accepted = 0
    for ref, other in pairs:
        picker = FramePicker(config.pick, terrain_scene_depth(world))
        picker.push(other)
        accepted += picker.push(ref).partner is other
    matcher = StereoMatcher(config.match)
    rel, coverage = [], []
    for ref, other in pairs:
        cloud, _ = matcher.cloud(ref, other)
        s = score(cloud, ref, scale=config.match.scale)
        rel.append(s.rel_errors)
        coverage.append(s.coverage)
    t0 = time.perf_counter()
    for _ in range(repeats):
        for ref, other in pairs:
            matcher.cloud(ref, other)
    ours = repeats * len(pairs) / (time.perf_counter() - t0)
    canon = [matcher.disparity(ref, other).pair for ref, other in pairs]
    t0 = time.perf_counter()
    for _ in range(repeats):
        for pair in canon:
            matcher.sgbm_only(pair)
    reference = repeats * len(pairs) / (time.perf_counter() - t0)
    rel_all = np.concatenate(rel)
    return {
        "size": f"{width}x{height}", "pairs": len(pairs), "picker_accepted": accepted,
        "precision": round(float((rel_all <= 0.05).mean()), 4),
        "precision_worst_pair": round(float(min((r <= 0.05).mean() for r in rel)), 4),
        "coverage": round(float(np.mean(coverage)), 4), "coverage_worst_pair": round(float(min(coverage)), 4),
        "median_abs_rel_error": round(float(np.median(rel_all)), 5),
        "pairs_per_s": round(ours, 2), "opencv_sgbm_only_pairs_per_s": round(reference, 2),
        "ratio_vs_sgbm_only": round(ours / reference, 3),
        "matching_scale": config.match.scale, "num_disparities": config.match.num_disparities,
    }


def main(sizes: list[tuple[int, int]], repeats: int, seed: int) -> dict:
    from layerpilot.sim import World, WorldConfig

    world = World(WorldConfig(seed=seed))
    results = []
    for w, h in sizes:
        res = run_size(world, w, h, repeats)
        results.append(res)
        print(f"{res['size']:>8}: precision {res['precision']:.3f} (worst pair {res['precision_worst_pair']:.3f})  "
              f"coverage {res['coverage']:.3f} (worst {res['coverage_worst_pair']:.3f})  "
              f"median |rel err| {res['median_abs_rel_error']:.4f}  {res['pairs_per_s']:.1f} pairs/s "
              f"(OpenCV SGBM alone {res['opencv_sgbm_only_pairs_per_s']:.1f}/s, ratio {res['ratio_vs_sgbm_only']:.2f})  "
              f"picker accepted {res['picker_accepted']}/{res['pairs']}")
    out = {"bench": "depth", "seed": seed, "repeats": repeats, "cpus": os.cpu_count(),
           "load_avg_1min": round(os.getloadavg()[0], 2), "sizes": results}
    print(json.dumps(out))
    return out
