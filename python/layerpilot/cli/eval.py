"""Evaluation commands: `layerpilot demo` (one scored mission) and `layerpilot study` (behaviors compared)."""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import warnings
from pathlib import Path

# option dest -> the mission key it overrides (a flag that is not given leaves the file's value)
MAX_DRONES = 8  # a lock-step fleet: one simulator, renderer and depth service per drone in one process
EVAL_FLAGS = {"behavior": "decide.behavior", "seed": "decide.seed", "duration": "evaluation.duration",
              "world_seed": "sim.world.seed", "world_size": "sim.world.size", "pitch": "sim.camera.pitch_deg",
              "frame_rate": "sim.frame_rate_hz", "depth": "depth.source", "sensors": "sim.sensors", "out": "evaluation.out",
              "seeds": "evaluation.seeds", "behaviors": "evaluation.behaviors"}


def _camera(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    return width, height


def _names(text: str) -> list[str]:
    return [b.strip() for b in text.split(",") if b.strip()]


def _seeds(text: str) -> list[int]:
    try:
        seeds = [int(v) for v in _names(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated whole numbers, got {text!r}") from None
    if not seeds or len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"expected distinct seeds, got {text!r}")
    return seeds


def _fleet_sizes(text: str) -> list[int]:
    try:
        sizes = [int(v) for v in _names(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated drone counts, got {text!r}") from None
    if not sizes or min(sizes) < 1 or max(sizes) > MAX_DRONES or len(set(sizes)) != len(sizes):
        raise argparse.ArgumentTypeError(f"expected distinct drone counts in [1, {MAX_DRONES}], got {text!r}")
    return sizes


def fleet(mission, drones: int):
    """The mission flown by ``drones`` vehicles: its own names first, then uav<k> for the rest."""
    names = list(mission.vehicles[:drones])
    k = 1
    while len(names) < drones:
        if f"uav{k}" not in names:
            names.append(f"uav{k}")
        k += 1
    return dataclasses.replace(mission, vehicles=names)


def _mission_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="mission file or name in config/missions/ (default: default); "
                   "the flags below override its fields")
    p.add_argument("--duration", type=float, help="simulated seconds (mission: evaluation.duration)")
    p.add_argument("--world-seed", type=int, help="procedural forest seed (sim.world.seed)")
    p.add_argument("--world-size", type=float, help="world square side in m (sim.world.size)")
    p.add_argument("--camera", type=_camera, help="camera image size WIDTHxHEIGHT (sim.camera.width, height)")
    p.add_argument("--pitch", type=float, help="camera pitch below the horizon in deg (sim.camera.pitch_deg)")
    p.add_argument("--frame-rate", type=float, help="camera frames per simulated second (sim.frame_rate_hz)")
    p.add_argument("--depth", type=lambda v: "ground_truth" if v == "truth" else v,  # "truth": its old name
                   choices=["stereo", "ground_truth"],
                   help="mission map from two-view stereo or from the renderer's depth (depth.source)")
    p.add_argument("--sensors", help="the simulated drone's sensor profile: perfect, rtk, consumer or degraded "
                   "(sim.sensors, docs/sim.md)")
    p.add_argument("--out", help="parent directory of the run directory (evaluation.out)")


def register(commands: argparse._SubParsersAction) -> None:
    demo = commands.add_parser("demo", help="fly one scored simulated mission (lock-step) and write its report")
    demo.add_argument("--behavior", help="behavior preset (a scripted baseline too) or .toml path (decide.behavior)")
    demo.add_argument("--seed", type=int, help="decision seed (decide.seed)")
    demo.add_argument("--name", default=None, help="run directory name (default: demo-BEHAVIOR)")
    demo.add_argument("--view", nargs="?", const="native", choices=["native", "web"],
                      help="show the mission in Rerun as it flies: the native viewer, or `web` "
                           "(docs/view.md: bind addresses)")
    demo.add_argument("--web-port", type=int, default=9090, help="--view web: the viewer page's port (default 9090)")
    demo.add_argument("--no-rrd", action="store_true", help="do not save the run's Rerun recording (mission.rrd)")
    demo.add_argument("--drones", type=int, help=f"vehicles in the fleet, 1-{MAX_DRONES} (default: the mission's "
                      "vehicles); one map, each drone avoids the others' targets")
    _mission_options(demo)
    demo.set_defaults(func=_demo)

    study = commands.add_parser("study", help="compare behaviors over several seeds (the paper's six by default)")
    study.add_argument("--behaviors", type=_names, help="comma-separated list (evaluation.behaviors); "
                       "'default' is the mission's own decide.behavior")
    study.add_argument("--seeds", type=int, help="decision seeds per MCDM behavior (evaluation.seeds)")
    study.add_argument("--world-seeds", type=_seeds, help="comma-separated forest seeds: every behavior flies "
                       "each world (default: the mission's sim.world.seed); tables give mean ± std over all runs")
    study.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="missions in parallel")
    study.add_argument("--name", default="study", help="run directory name")
    study.add_argument("--quick", action="store_true", help="short version for CI: 60 s, 1 seed, 160x120 camera")
    study.add_argument("--no-rrd", action="store_true", help="do not save each run's Rerun recording (mission.rrd)")
    study.add_argument("--drones", type=_fleet_sizes, help="comma-separated fleet sizes: every behavior flies "
                       "with each (rows 'BEHAVIOR xN'; default: the mission's vehicles)")
    _mission_options(study)
    study.set_defaults(func=_study)


def _mission(args: argparse.Namespace):
    """The mission file with the given flags applied; errors name the flag."""
    from layerpilot.cli.nodes import mission_from_args
    from layerpilot.missionfile import Override

    camera = [] if args.camera is None else [Override("--camera", "sim.camera.width", args.camera[0]),
                                             Override("--camera", "sim.camera.height", args.camera[1])]
    return mission_from_args(args, EVAL_FLAGS, camera)


def _table(rows: dict[str, dict[str, float]]) -> str:
    from layerpilot.eval.report import format_value
    from layerpilot.eval.summary import label

    names = [k for k in dict.fromkeys(k for r in rows.values() for k in r) if k != "t"]  # a fleet's rows add some
    width = max(len(label(n)) for n in names)
    lines = [" " * width + "  " + "  ".join(f"{name:>12}" for name in rows)]
    for n in names:
        lines.append(f"{label(n):>{width}}  " + "  ".join(f"{format_value(r.get(n, math.nan)):>12}"
                                                          for r in rows.values()))
    return "\n".join(lines)


def _demo(args: argparse.Namespace) -> None:
    mission = _mission(args)
    if args.drones is not None:
        if not 1 <= args.drones <= MAX_DRONES:
            raise ValueError(f"--drones must be in [1, {MAX_DRONES}], got {args.drones}")
        mission = fleet(mission, args.drones)
    behavior = mission.decide.behavior
    result = _run(mission, Path(mission.evaluation.out) / (args.name or f"demo-{Path(behavior).stem}"),
                  rrd=not args.no_rrd, web_port=args.web_port if args.view == "web" else None,
                  spawn=args.view == "native")
    print(_table({behavior: result.final}))
    flown = result.final["t"]  # the duration, or less when the pilot came home for the battery
    print(f"{flown:.0f} simulated s in {result.wall_s:.1f} s wall ({flown / result.wall_s:.1f}x real "
          f"time); {result.waypoints} waypoints, {result.frames} frames, {result.clouds} {mission.depth.source} clouds")
    print(f"report: {result.report['html']}")


def _run(mission, run_dir: str | Path, progress_stream=None, *, rrd: bool = True, web_port: int | None = None,
         spawn: bool = False):
    """run_mission with its Rerun recording beside the report (mission.rrd) and, when asked, a live viewer."""
    from layerpilot.eval.mission import run_mission

    view = None
    if rrd or web_port is not None or spawn:
        from layerpilot.viz.lockstep import LockstepView

        view = LockstepView.open(Path(run_dir).name, save=Path(run_dir) / "mission.rrd" if rrd else None,
                                 web_port=web_port, spawn=spawn)
        if view.url:
            print(f"viewer: {view.url}", flush=True)
    try:
        return run_mission(mission, run_dir, progress_stream, view=view)
    finally:
        if view is not None:
            view.close()


def _one(mission, run_dir: str, rrd: bool) -> tuple[str, dict[str, float], float]:
    """A study mission in a worker process (its progress bar silenced; the parent reports)."""
    with open(os.devnull, "w") as quiet:
        result = _run(mission, run_dir, progress_stream=quiet, rrd=rrd)
    return run_dir, result.final, result.wall_s


def _study(args: argparse.Namespace) -> None:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    import numpy as np

    from layerpilot.eval.summary import write_study_report
    from layerpilot.missionfile import to_settings
    from layerpilot.decide.behavior import load_behavior
    from layerpilot.progress import Progress

    if args.quick:
        args.duration, args.seeds, args.camera = min(args.duration or 60.0, 60.0), 1, (160, 120)
    if args.jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    mission = _mission(args)
    behaviors = [mission.decide.behavior if b == "default" else b for b in mission.evaluation.behaviors]
    ev = dataclasses.replace(mission.evaluation, behaviors=list(dict.fromkeys(behaviors)))
    out = Path(ev.out) / args.name
    jobs: list[tuple[str, object, str]] = []
    worlds = args.world_seeds or [mission.sim.world.seed]
    sizes = args.drones or [len(mission.vehicles)]
    rows = {(b, n): b if sizes == [1] else f"{b} x{n}" for b in ev.behaviors for n in sizes}  # the table's rows
    for world in worlds:
        sim = dataclasses.replace(mission.sim, world=dataclasses.replace(mission.sim.world, seed=world))
        for (behavior, drones), row in rows.items():
            # A pattern that only repeats has no decision noise: one run per world stands for every seed.
            for seed in range(1 if load_behavior(behavior).deterministic else ev.seeds):
                decide = dataclasses.replace(mission.decide, behavior=behavior, seed=seed)
                run = fleet(dataclasses.replace(mission, decide=decide, sim=sim), drones)
                name = Path(row.replace(" x", "-x")).stem + ("" if args.world_seeds is None else f"-w{world}") + \
                    f"-s{seed}"
                jobs.append((row, run, str(out / "runs" / name)))
    runs: dict[str, list[str]] = {row: [] for row in rows.values()}
    finals: dict[str, list[dict[str, float]]] = {row: [] for row in rows.values()}
    progress = Progress(len(jobs), f"study ({len(jobs)} missions, {args.jobs} at a time)", " runs")
    progress.update(0)
    context = multiprocessing.get_context("spawn")  # fresh GL context and sockets per worker
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=context) as pool:
        futures = {pool.submit(_one, m, run_dir, not args.no_rrd): behavior for behavior, m, run_dir in jobs}
        for done, future in enumerate(as_completed(futures), start=1):
            run_dir, final, wall = future.result()
            runs[futures[future]].append(run_dir)
            finals[futures[future]].append(final)
            progress.update(done, f"{Path(run_dir).name} {final['percent_mapped']:.1f}% mapped in {wall:.0f}s")
    runs = {b: sorted(d) for b, d in runs.items()}
    shared = {k: v for k, v in to_settings(mission).items() if k not in ("decide.behavior", "decide.seed")}
    if args.world_seeds is not None:
        shared["sim.world.seed"] = ", ".join(map(str, worlds))
    flown = {row: dataclasses.replace(mission.decide, behavior=b).flown_behavior().summary() for (b, _), row in
             rows.items()}
    paths = write_study_report(out, runs, {**shared, "quick": args.quick}, flown)
    with warnings.catch_warnings():  # a metric that is NaN in every seed stays NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        means = {b: {k: float(np.nanmean([f[k] for f in fs])) for k in fs[0]} for b, fs in finals.items()}
    print("mean over worlds and seeds:" if args.world_seeds else "mean over seeds:")
    print(_table(means))
    print(f"report: {paths['html']}")
