"""Every demo run saves its Rerun recording beside the report; without a view nothing loads rerun."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections import Counter

from rerun.chunk import RrdReader

from layerpilot.cli.eval import _run
from layerpilot.mission.config import Override, load_mission

ENTITIES = ["/world/map", "/world/drone", "/world/path", "/world/camera", "/world/target", "/world/runner_up",
            "/world/area", "/decision", "/layers/color", "/layers/elevation", "/layers/time_since_seen",
            "/layers/distance", "/metrics/percent_mapped", "/metrics/avg_time_since_observed",
            "/metrics/avg_min_distance"]


def test_demo_run_saves_an_rrd_with_the_mission_entities(tmp_path):
    """The demo command's own path (cli.eval._run): run_mission with a LockstepView saving beside the report."""
    mission = load_mission("default", [Override("--duration", "evaluation.duration", 8.0),
                                       Override("--camera", "sim.camera", {"width": 160, "height": 120}),
                                       Override("--depth", "depth.source", "ground_truth")])
    run = tmp_path / "d"
    with open(os.devnull, "w") as quiet:
        _run(mission, run, progress_stream=quiet)
    rows: Counter[str] = Counter()
    for chunk in RrdReader(run / "mission.rrd").stream():
        rows[chunk.entity_path] += chunk.num_rows
    missing = [e for e in ENTITIES if rows[e] == 0]
    assert not missing, f"missing entities {missing}; the file has {sorted(rows)}"
    decisions = (run / "decisions.jsonl").read_text().splitlines()
    assert rows["/decision"] == rows["/world/target"] == len(decisions) > 0  # one explanation per command
    assert rows["/world/drone"] == json.loads((run / "metrics.json").read_text())["settings"]["frames"]
    chosen = sum("explanation" in json.loads(d) for d in decisions)  # the maker's (not the way home's)
    for name in ("A0", "A1", "A2", "A3"):  # each tick's aggregates, placed on the layers: transform + image
        assert rows[f"/layers/{name}"] == 2 * chosen > 0, name


def test_nodes_and_evaluator_do_not_load_rerun_unless_asked():
    code = ("import sys\n"
            "import layerpilot.cli, layerpilot.eval.mission, layerpilot.eval.replay, layerpilot.bus.recording\n"
            "from layerpilot.nodes import decide, map_server, up, link, sim, depth\n"
            "layerpilot.cli.build_parser()\n"
            "print('rerun' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
