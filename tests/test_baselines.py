"""The scripted baselines fly in lock-step (`layerpilot study`) as planned: the pattern's waypoints in order,
reached, at the camera mount the behavior states; survey-refly then flies its next flights over the gaps."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from layerpilot.config import ConfigError
from layerpilot.decide.behavior import PRESET_DIR
from layerpilot.mission.build import build_pilot
from layerpilot.missionfile import Override, load_mission, to_settings

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ["survey", "survey-side", "orbit-rings"]


def small_refly(tmp_path: Path) -> Path:
    """survey-refly over a 40 m disc: one survey line, so the pass ends early and the replanning shows."""
    text = (PRESET_DIR / "survey-refly.toml").read_text().replace("radius = 100.0", "radius = 40.0")
    path = tmp_path / "refly-small.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("baselines")
    refly = small_refly(tmp)
    done = subprocess.run([sys.executable, "-m", "layerpilot.cli", "study", "--camera", "160x120", "--seeds", "1", "--duration", "80", "--no-rrd",
                           "--behaviors", ",".join(SHIPPED + [str(refly)]), "--out", str(tmp)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600,
                          env={"PYTHONPATH": str(ROOT / "python"), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr[-2000:]
    return tmp / "study" / "runs", refly


def _run(runs: Path, name: str) -> tuple[list[dict], dict]:
    run = next(runs.glob(f"{name}-s0"))
    decisions = [json.loads(line) for line in (run / "decisions.jsonl").read_text().splitlines()]
    return decisions, json.loads((run / "metrics.json").read_text())


@pytest.mark.parametrize("behavior", SHIPPED)
def test_a_baseline_flies_its_pattern_in_lock_step(study, behavior) -> None:
    runs, _ = study
    decisions, metrics = _run(runs, behavior)
    settings = metrics["settings"]
    mission = load_mission(None, [Override("--behavior", "decide.behavior", behavior),
                                  Override("--camera", "sim.camera.width", 160),
                                  Override("--camera", "sim.camera.height", 120)])
    pattern = build_pilot(mission.core).pattern
    assert settings["reached"] >= 2 and len(decisions) == settings["reached"] + 1
    for d, want in zip(decisions, pattern):
        assert d["scripted"] and d["waypoint"] == pytest.approx(list(want[:3])) and d["yaw"] == pytest.approx(want[3])
    assert settings["sim.camera.pitch_deg"] == (90.0 if behavior == "survey" else 60.0)
    assert metrics["final"]["percent_mapped"] > 0


def test_survey_refly_plans_its_next_flight_over_the_gaps_after_the_pass(study) -> None:
    runs, refly = study
    decisions, metrics = _run(runs, refly.stem)
    mission = load_mission(None, [Override("--behavior", "decide.behavior", str(refly))])
    pattern = build_pilot(mission.core).pattern
    assert len(pattern) == 2  # one line across the 40 m disc
    assert metrics["settings"]["replans"] >= 1
    after = [d["waypoint"] for d in decisions[len(pattern):]]
    assert after and all(np.hypot(x, y) <= 40.0 + 1e-6 for x, y, _ in after)  # inside the area
    assert not any(np.allclose(w, p[:3]) for w in after for p in pattern)  # not the pattern again


def test_the_behaviors_mount_is_the_simulated_cameras_and_a_contrary_pitch_flag_is_refused() -> None:
    survey = load_mission(None, [Override("--behavior", "decide.behavior", "survey")])
    assert survey.core.camera.pitch_deg == 90.0 and survey.simulator.camera.pitch_deg == 90.0
    assert to_settings(survey)["sim.camera.pitch_deg"] == 90.0 and survey.sim.camera.pitch_deg == 60.0
    with pytest.raises(ConfigError, match=r"^--pitch 70.0: behavior 'survey' flies its own camera mount "
                                          r"\(camera_pitch_deg = 90\)"):
        load_mission(None, [Override("--behavior", "decide.behavior", "survey"),
                            Override("--pitch", "sim.camera.pitch_deg", 70.0)])
    assert load_mission(None, [Override("--pitch", "sim.camera.pitch_deg", 70.0)]).core.camera.pitch_deg == 70.0


def test_terrain_following_keeps_the_stated_height_over_a_ridge() -> None:
    """The ridges mission's survey over its mapped world (the true surface, trees included, in a real
    VoxelMap): every waypoint clears the highest surface near its leg by exactly the stated 30 m,
    unless the limits clip it, so it is never lower than 30 m above the surface under it."""
    from layerpilot.grid import GridGeometry
    from layerpilot.map import VoxelMap
    from layerpilot.sim.world import World

    mission = load_mission("ridges", [Override("--behavior", "decide.behavior", "survey")])
    world = World(mission.sim.world)
    g = GridGeometry(-260.0, -260.0, 1.0, 520, 520)
    top = world.surface_height(g) - float(world.terrain_height(0.0, 0.0))  # map frame: home's ground is 0
    xs, ys = g.cell_centers()
    voxels = VoxelMap(1.0)
    for r in range(0, g.height, 20):  # seen from 10 m above each 20 m tile
        for c in range(0, g.width, 20):
            tile = np.s_[r:r + 20, c:c + 20]
            cloud = np.column_stack([xs[tile].ravel(), ys[tile].ravel(), top[tile].ravel() - 0.5])
            voxels.insert(cloud.astype(np.float32), np.array([xs[tile].mean(), ys[tile].mean(), top[tile].max() + 10]),
                          stamp=1.0)
    columns = voxels.column_layers_for(g)
    assert np.nanmax(top) - np.nanmin(top) > 60.0  # a ridge, trees on it
    pilot = build_pilot(mission.core)
    terrain = pilot.behavior.terrain
    assert terrain.enabled and terrain.clearance == 30.0
    position, lowest, exact = (0.0, 0.0, 30.0), np.inf, 0
    for k in range(len(pilot.pattern)):
        c = pilot.step(position, float(k), columns)
        x, y, z = c.position
        (sx, sy), (dx, dy) = position[:2], (x - position[0], y - position[1])
        t = np.clip(((xs - sx) * dx + (ys - sy) * dy) / max(dx * dx + dy * dy, 1e-12), 0, 1)
        near = (np.hypot(xs - sx - t * dx, ys - sy - t * dy) <= 10.0 + 0.5 * np.sqrt(2)).ravel()  # a cell touching
        highest = float(columns.elevation.ravel()[near].max())
        exact += z == pytest.approx(highest + 30.0, abs=1e-4)
        assert z == pytest.approx(np.clip(highest + 30.0, terrain.min_altitude, terrain.max_altitude), abs=1e-4)
        i, j = g.cell_of(x, y)
        lowest = min(lowest, z - float(top[i, j]))
        position = c.position
    assert exact >= 0.9 * len(pilot.pattern) and lowest >= 30.0 - 1.0


def test_the_study_report_names_every_behaviors_settings_as_flown(study) -> None:
    runs, refly = study
    page = (runs.parent / "report.md").read_text()
    assert "## Behaviors as flown" in page
    assert ("| survey | area circle r 100 m; altitude 50 m; camera 90° down; pattern survey; side overlap 0.3; "
            "front overlap stereo baseline |") in page
    assert f"| {refly} | area circle r 40 m;" in page and "then replan (stale after 150 s); weights fringe 1" in page
