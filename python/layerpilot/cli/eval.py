"""Evaluation commands: `layerpilot demo` (one scored mission) and `layerpilot study` (behaviors compared)."""

from __future__ import annotations

import argparse
import os
import warnings
from dataclasses import asdict
from pathlib import Path

BEHAVIORS = ["balanced", "exploration", "time", "distance", "lawnmower", "orbit"]


def _mission_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=600.0, help="simulated seconds (default 600)")
    p.add_argument("--world-seed", type=int, default=0, help="procedural forest seed")
    p.add_argument("--world-size", type=float, default=400.0, help="world square side (m)")
    p.add_argument("--camera", default="320x240", help="camera image size WIDTHxHEIGHT (default 320x240)")
    p.add_argument("--pitch", type=float, default=60.0, help="camera pitch below the horizon (deg)")
    p.add_argument("--frame-rate", type=float, default=1.0, help="camera frames per simulated second")
    p.add_argument("--depth", choices=["stereo", "truth"], default="stereo",
                   help="mission map from two-view stereo (default) or from ground-truth depth")
    p.add_argument("--out", type=Path, default=Path("runs"), help="parent directory of the run directory")


def register(commands: argparse._SubParsersAction) -> None:
    demo = commands.add_parser("demo", help="fly one scored simulated mission and write its report")
    demo.add_argument("--behavior", default="balanced", help=f"preset, .toml path, or baseline ({', '.join(BEHAVIORS)})")
    demo.add_argument("--seed", type=int, default=0, help="decision seed")
    demo.add_argument("--name", default=None, help="run directory name (default: demo-BEHAVIOR)")
    _mission_options(demo)
    demo.set_defaults(func=_demo)

    study = commands.add_parser("study", help="compare the paper's six behaviors over several seeds")
    study.add_argument("--behaviors", default=",".join(BEHAVIORS), help="comma-separated list")
    study.add_argument("--seeds", type=int, default=3, help="decision seeds per MCDM behavior (default 3)")
    study.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="missions in parallel")
    study.add_argument("--name", default="study", help="run directory name")
    study.add_argument("--quick", action="store_true", help="short version for CI: 60 s, 1 seed, 160x120 camera")
    _mission_options(study)
    study.set_defaults(func=_study)


def _config(args: argparse.Namespace, behavior: str, seed: int):
    from layerpilot.eval.mission import MissionConfig

    try:
        width, height = (int(v) for v in args.camera.lower().split("x"))
    except ValueError:
        raise ValueError(f"--camera: expected WIDTHxHEIGHT, got {args.camera!r}") from None
    return MissionConfig(behavior=behavior, duration=args.duration, seed=seed, world_seed=args.world_seed,
                         world_size=args.world_size, camera_width=width, camera_height=height,
                         camera_pitch_deg=args.pitch, frame_rate_hz=args.frame_rate, depth=args.depth)


def _table(rows: dict[str, dict[str, float]]) -> str:
    from layerpilot.eval.pictures.plots import LABELS
    from layerpilot.eval.report import format_value

    names = [k for k in next(iter(rows.values())) if k != "t"]
    width = max(len(LABELS.get(n, n)) for n in names)
    lines = [" " * width + "  " + "  ".join(f"{label:>12}" for label in rows)]
    for n in names:
        lines.append(f"{LABELS.get(n, n):>{width}}  " + "  ".join(f"{format_value(r[n]):>12}" for r in rows.values()))
    return "\n".join(lines)


def _demo(args: argparse.Namespace) -> None:
    from layerpilot.eval.mission import run_mission

    cfg = _config(args, args.behavior, args.seed)
    result = run_mission(cfg, args.out / (args.name or f"demo-{Path(args.behavior).stem}"))
    print(_table({cfg.behavior: result.final}))
    print(f"{cfg.duration:.0f} simulated s in {result.wall_s:.1f} s wall ({cfg.duration / result.wall_s:.1f}x real "
          f"time); {result.waypoints} waypoints, {result.frames} frames, {result.clouds} stereo clouds")
    print(f"report: {result.report['html']}")


def _one(cfg, run_dir: str) -> tuple[str, dict[str, float], float]:
    """A study mission in a worker process (its progress bar silenced; the parent reports)."""
    from layerpilot.eval.mission import run_mission

    with open(os.devnull, "w") as quiet:
        result = run_mission(cfg, run_dir, progress_stream=quiet)
    return run_dir, result.final, result.wall_s


def _study(args: argparse.Namespace) -> None:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    import numpy as np

    from layerpilot.eval.mission import BASELINES
    from layerpilot.eval.summary import write_study_report
    from layerpilot.progress import Progress

    if args.quick:
        args.duration, args.seeds, args.camera = min(args.duration, 60.0), 1, "160x120"
    behaviors = [b.strip() for b in args.behaviors.split(",") if b.strip()]
    if not behaviors or args.seeds < 1 or args.jobs < 1:
        raise ValueError("--behaviors, --seeds and --jobs need at least one each")
    out = args.out / args.name
    jobs: list[tuple[str, object, str]] = []
    for behavior in behaviors:
        # Scripted baselines have no decision noise: one run stands for every seed.
        for seed in range(1 if behavior in BASELINES else args.seeds):
            jobs.append((behavior, _config(args, behavior, seed), str(out / "runs" / f"{Path(behavior).stem}-s{seed}")))
    runs: dict[str, list[str]] = {b: [] for b in behaviors}
    finals: dict[str, list[dict[str, float]]] = {b: [] for b in behaviors}
    progress = Progress(len(jobs), f"study ({len(jobs)} missions, {args.jobs} at a time)", " runs")
    progress.update(0)
    context = multiprocessing.get_context("spawn")  # fresh GL context and sockets per worker
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=context) as pool:
        futures = {pool.submit(_one, cfg, run_dir): behavior for behavior, cfg, run_dir in jobs}
        for done, future in enumerate(as_completed(futures), start=1):
            run_dir, final, wall = future.result()
            runs[futures[future]].append(run_dir)
            finals[futures[future]].append(final)
            progress.update(done, f"{Path(run_dir).name} {final['percent_mapped']:.1f}% mapped in {wall:.0f}s")
    runs = {b: sorted(d) for b, d in runs.items()}
    settings = {k: v for k, v in asdict(_config(args, "-", 0)).items() if k not in ("behavior", "seed")}
    paths = write_study_report(out, runs, {**settings, "seeds": args.seeds, "quick": args.quick})
    with warnings.catch_warnings():  # a metric that is NaN in every seed stays NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        means = {b: {k: float(np.nanmean([f[k] for f in fs])) for k in fs[0]} for b, fs in finals.items()}
    print("mean over seeds:")
    print(_table(means))
    print(f"report: {paths['html']}")
