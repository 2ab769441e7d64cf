"""`layerpilot bench depth`: accuracy and speed of stereo depth on a fixed set of rendered pairs.

For each image size the measured preset runs on ``BENCH_PAIRS`` (altitudes 30-60 m,
pitch 45-90 deg, default forest). Accuracy is pooled over all points of all pairs;
speed is wall time of rectification + matching + filtering + reprojection, and the same
with the live pose refinement in front (``depth.live``: tracks, essential matrix, polish,
sliding-window adjustment, as the depth service runs it), next to OpenCV's bare StereoSGBM
(one call on the same rectified images, without its left-right check) as the reference.
The three are timed pair by pair in turn, so that a busy machine slows them alike.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from layerpilot.depth.config import DepthConfig, preset_for
from layerpilot.depth.evaluate import score
from layerpilot.depth.live import LiveRefiner
from layerpilot.depth.picking import FramePicker
from layerpilot.depth.stereo import StereoMatcher
from layerpilot.eval.fixtures import BENCH_PAIRS, render_pair, terrain_scene_depth


def run_size(world, width: int, height: int, repeats: int) -> dict:
    import dataclasses

    from layerpilot.camera import CameraConfig
    from layerpilot.sim import Renderer

    config: DepthConfig = preset_for(width)
    with Renderer(world, CameraConfig(width=width, height=height)) as r:
        pairs = [render_pair(r, dataclasses.replace(s, ratio=config.pick.target_baseline_ratio), stamp=1.0)
                 for s in BENCH_PAIRS]
    accepted = 0
    for ref, other in pairs:
        picker = FramePicker(config.pick, terrain_scene_depth(world))
        picker.push(other)
        accepted += picker.push(ref).partner is other
    # distinct stamps: the refiner keys its keyframes by stamp
    pairs = [(dataclasses.replace(ref, stamp=2.0 * k + 1), dataclasses.replace(other, stamp=2.0 * k))
             for k, (ref, other) in enumerate(pairs)]
    matcher = StereoMatcher(config.match)
    rel, coverage, rel_refined = [], [], []
    refiner = LiveRefiner()
    for ref, other in pairs:
        cloud, _ = matcher.cloud(ref, other)
        s = score(cloud, ref, scale=config.match.scale)
        rel.append(s.rel_errors)
        coverage.append(s.coverage)
        refined = refiner.refine(ref, other)
        if refined is not None:
            rel_refined.append(score(matcher.cloud(*refined)[0], ref, scale=config.match.scale).rel_errors)
    canon = [matcher.disparity(ref, other).pair for ref, other in pairs]
    spent = np.zeros(3)  # ours, ours with refinement, bare SGBM
    for rep in range(repeats):
        refiner = LiveRefiner()
        for k, ((ref, other), pair) in enumerate(zip(pairs, canon)):
            # a new stamp per repeat: each pair is a new pair of frames to the refiner
            ref, other = (dataclasses.replace(f, stamp=f.stamp + 100.0 * rep) for f in (ref, other))
            t0 = time.perf_counter()
            matcher.cloud(ref, other)
            t1 = time.perf_counter()
            if (refined := refiner.refine(ref, other)) is not None:
                matcher.cloud(*refined)
            t2 = time.perf_counter()
            matcher.sgbm_only(pair)
            spent += (t1 - t0, t2 - t1, time.perf_counter() - t2)
    ours, ours_refined, reference = repeats * len(pairs) / spent
    rel_all = np.concatenate(rel)
    return {
        "size": f"{width}x{height}", "pairs": len(pairs), "picker_accepted": accepted,
        "precision": round(float((rel_all <= 0.05).mean()), 4),
        "precision_worst_pair": round(float(min((r <= 0.05).mean() for r in rel)), 4),
        "coverage": round(float(np.mean(coverage)), 4), "coverage_worst_pair": round(float(min(coverage)), 4),
        "median_abs_rel_error": round(float(np.median(rel_all)), 5),
        "refined_pairs": len(rel_refined),
        "precision_refined": round(float((np.concatenate(rel_refined) <= 0.05).mean()), 4) if rel_refined else None,
        "pairs_per_s": round(ours, 2), "pairs_per_s_refined": round(ours_refined, 2),
        "opencv_sgbm_only_pairs_per_s": round(reference, 2),
        "ratio_vs_sgbm_only": round(ours / reference, 3), "ratio_refined_vs_sgbm_only": round(ours_refined / reference, 3),
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
              f"median |rel err| {res['median_abs_rel_error']:.4f}  {res['pairs_per_s']:.1f} pairs/s, "
              f"{res['pairs_per_s_refined']:.1f} with refinement (precision {res['precision_refined']}, "
              f"{res['refined_pairs']}/{res['pairs']} refined); OpenCV SGBM alone {res['opencv_sgbm_only_pairs_per_s']:.1f}/s, "
              f"ratio {res['ratio_vs_sgbm_only']:.2f}, with refinement {res['ratio_refined_vs_sgbm_only']:.2f}  "
              f"picker accepted {res['picker_accepted']}/{res['pairs']}")
    out = {"bench": "depth", "seed": seed, "repeats": repeats, "cpus": os.cpu_count(),
           "load_avg_1min": round(os.getloadavg()[0], 2), "sizes": results}
    print(json.dumps(out))
    return out
