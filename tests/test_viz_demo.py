"""Every demo run saves its Rerun recording beside the report; without a view nothing loads rerun."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections import Counter

import cv2
import numpy as np
from rerun.chunk import RrdReader

from layerpilot.cli.eval import _run
from layerpilot.decide import area_geometry
from layerpilot.missionfile import Override, load_mission
from layerpilot.viz.scene import aggregate_colors
from conftest import balanced_behavior

ENTITIES = ["/world/map", "/world/drone", "/world/path", "/world/camera", "/world/target", "/world/runner_up",
            "/world/area", "/decision", "/layers/color", "/layers/elevation", "/layers/time_since_seen",
            "/layers/distance", "/metrics/percent_mapped", "/metrics/avg_time_since_observed",
            "/metrics/avg_min_distance"]


def test_demo_run_saves_an_rrd_with_the_mission_entities(tmp_path):
    """The demo command's own path (cli.eval._run): run_mission with a LockstepView saving beside the report."""
    # balanced with the paper's r_i of 100 m, so that a tick's window is smaller than the 240 m grid
    behavior = balanced_behavior(tmp_path, "balanced-100.toml", head="r_e = 10.0\nr_i = 100.0\n")
    mission = load_mission("default", [Override("--behavior", "decide.behavior", behavior),
                                       Override("--duration", "evaluation.duration", 8.0),
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
    chosen = [d for d in map(json.loads, decisions) if "explanation" in d]  # the maker's (not the way home's)
    for name in ("A0", "A1", "A2", "A3"):  # each tick's aggregates, placed on the layers: transform + image
        assert rows[f"/layers/{name}"] == 2 * len(chosen) > 0, name
    # placed where the tick computed them: the chosen cell, inside the window drawn, has (about) its top score
    behavior = mission.decide.flown_behavior()
    under = area_geometry(behavior.area, mission.decide.home, resolution=mission.map_server.resolution)
    batches = [c.to_record_batch() for c in RrdReader(run / "mission.rrd").stream() if c.entity_path == "/layers/A3"]

    def column(name: str) -> list:
        return [x[0] for b in batches if name in b.schema.names for x in b.column(name).to_pylist() if x is not None]

    placed, images = column("Transform3D:translation"), column("EncodedImage:blob")
    assert len(placed) == len(images) == len(chosen)
    top_colors = {tuple(c) for c in aggregate_colors()[-3:]}  # within 2 of AGGREGATE_LEVELS steps of the maximum
    for (left, top, _), blob, d in zip(placed, images, chosen):
        bgra = cv2.imdecode(np.frombuffer(bytes(blob), np.uint8), cv2.IMREAD_UNCHANGED)
        rgba = cv2.cvtColor(bgra, cv2.COLOR_BGRA2RGBA)
        u = (d["waypoint"][0] - under.origin_x) / under.resolution - left
        v = (under.extent[3] - d["waypoint"][1]) / under.resolution - top
        assert 0 <= u < rgba.shape[1] and 0 <= v < rgba.shape[0], (left, top, u, v, rgba.shape)
        assert rgba.shape[0] < under.height  # the tick's window, not the whole grid
        if d["fallback"] is None:  # a fallback chose where every cell scored 0 (transparent)
            assert tuple(rgba[int(v), int(u)]) in top_colors, d["explanation"]
    assert any(d["fallback"] is None for d in chosen)


def test_nodes_and_evaluator_do_not_load_rerun_unless_asked():
    code = ("import sys\n"
            "import layerpilot.cli, layerpilot.eval.mission, layerpilot.eval.replay, layerpilot.bus.recording\n"
            "from layerpilot.nodes import decide, map_server, up, link, sim, depth\n"
            "layerpilot.cli.build_parser()\n"
            "print('rerun' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
