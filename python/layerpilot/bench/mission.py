"""`layerpilot bench mission`: a lock-step mission with its stages overlapped against the sequential order.

Both orders fly the same mission in the same run; the bench prints each one's real-time factor,
the ratio, and whether the two runs wrote the same bytes (decisions, map, metric series): the
overlap may only change how fast, never what.
"""

from __future__ import annotations

import hashlib
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

from layerpilot.eval.mission import run_mission
from layerpilot.missionfile import Mission

COMPARED = ("decisions.jsonl", "map.ot", "metrics.csv")


def _digest(run_dir: Path) -> dict[str, str]:
    return {name: hashlib.sha256((run_dir / name).read_bytes()).hexdigest() for name in COMPARED}


def main(mission: Mission) -> int:
    """Fly ``mission`` sequentially, then overlapped; 0 if the two runs are byte-identical."""
    duration = mission.evaluation.duration
    camera = mission.simulator.camera
    print(f"{mission.decide.behavior}, {duration:g} mission s, {camera.width}x{camera.height} camera, "
          f"world seed {mission.sim.world.seed}", flush=True)
    result: dict[str, object] = {"duration_s": duration, "camera": f"{camera.width}x{camera.height}"}
    digests = {}
    with tempfile.TemporaryDirectory(prefix="bench-mission-") as tmp:
        warm = replace(mission, evaluation=replace(mission.evaluation, duration=5.0))
        run_mission(warm, Path(tmp) / "warm-up", None)  # world, shaders and caches: neither order pays them
        for name, overlap in (("sequential", False), ("overlapped", True)):
            run = run_mission(mission, Path(tmp) / name, sys.stderr, overlap=overlap)
            digests[name] = _digest(run.run_dir)
            result[f"{name}_wall_s"] = round(run.wall_s, 1)
            result[f"{name}_real_time"] = round(duration / run.wall_s, 2)
            print(f"{name:>10}: {run.wall_s:6.1f} s wall, {duration / run.wall_s:5.2f}x real time", flush=True)
    result["speedup"] = round(result["sequential_wall_s"] / result["overlapped_wall_s"], 2)
    result["identical"] = digests["sequential"] == digests["overlapped"]
    print(f"overlapped is {result['speedup']:.2f}x the sequential order; results "
          f"{'byte-identical' if result['identical'] else 'DIFFER'} ({', '.join(COMPARED)})")
    print(json.dumps(result))
    return 0 if result["identical"] else 1
