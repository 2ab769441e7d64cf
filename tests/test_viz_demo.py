"""Every demo run saves its Rerun recording beside the report; without a view nothing loads rerun."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter

from rerun.chunk import RrdReader

ENTITIES = ["/world/map", "/world/drone", "/world/path", "/world/camera", "/world/target", "/world/runner_up",
            "/world/area", "/decision", "/layers/color", "/layers/elevation", "/layers/time_since_seen",
            "/layers/distance", "/metrics/percent_mapped", "/metrics/avg_time_since_observed",
            "/metrics/avg_min_distance"]


def test_demo_run_saves_an_rrd_with_the_mission_entities(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "layerpilot.cli", "demo", "--duration", "12", "--camera", "160x120",
                           "--depth", "ground_truth", "--frame-rate", "2", "--out", str(tmp_path), "--name", "d"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    run = tmp_path / "d"
    rows: Counter[str] = Counter()
    for chunk in RrdReader(run / "mission.rrd").stream():
        rows[chunk.entity_path] += chunk.num_rows
    missing = [e for e in ENTITIES if rows[e] == 0]
    assert not missing, f"missing entities {missing}; the file has {sorted(rows)}"
    decisions = (run / "decisions.jsonl").read_text().splitlines()
    assert rows["/decision"] == rows["/world/target"] == len(decisions) > 0  # one explanation per command
    assert rows["/world/drone"] == json.loads((run / "metrics.json").read_text())["settings"]["frames"]


def test_nodes_and_evaluator_do_not_load_rerun_unless_asked():
    code = ("import sys\n"
            "import layerpilot.cli, layerpilot.eval.mission, layerpilot.eval.replay, layerpilot.bus.recording\n"
            "from layerpilot.nodes import decide, map_server, up, link, sim, depth\n"
            "layerpilot.cli.build_parser()\n"
            "print('rerun' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
