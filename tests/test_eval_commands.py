"""`layerpilot demo` and `layerpilot study --quick` as a user runs them (real processes, real missions)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from layerpilot.eval.series import MetricSeries
from layerpilot.missionfile import load_mission
from layerpilot.sim.endpoint_config import SITL_DATUM
from layerpilot.sim.world import World

ROOT = Path(__file__).resolve().parents[1]


def _layerpilot(*args: str) -> str:
    done = subprocess.run([sys.executable, "-m", "layerpilot.cli", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=600, env={"PYTHONPATH": str(ROOT / "python"), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


@pytest.fixture(scope="module")
def demo(tmp_path_factory) -> tuple[str, Path]:
    """A short default-mission demo: what it printed, and its run directory."""
    tmp = tmp_path_factory.mktemp("demo")
    out = _layerpilot("demo", "--duration", "10", "--camera", "160x120", "--no-rrd", "--out", str(tmp), "--name", "d")
    return out, tmp / "d"


def test_demo_prints_metrics_and_report_path(demo) -> None:
    out, run = demo
    assert "area mapped (%)" in out and "3D F-score" in out
    assert f"report: {run / 'report.html'}" in out
    final = json.loads((run / "metrics.json").read_text())["final"]
    assert 0.0 < final["percent_mapped"] < 100.0


def test_layers_export_and_plan_next_place_a_demo_run_on_the_earth(demo) -> None:
    """The run's frame.json is the simulated autopilot's EKF origin: the SITL field, at the terrain under home."""
    _, run = demo
    frame = json.loads((run / "frame.json").read_text())
    ground = float(World(load_mission("default").sim.world).terrain_height(0.0, 0.0))
    assert frame["lat"] == pytest.approx(SITL_DATUM.lat, abs=1e-9) and frame["lon"] == pytest.approx(SITL_DATUM.lon,
                                                                                                       abs=1e-9)
    assert frame["alt"] == pytest.approx(SITL_DATUM.alt + ground, abs=1e-6) and abs(ground) > 1.0
    assert "CRS: layerpilot map frame at 47.3977420, 8.5455940" in _layerpilot("layers", "export", str(run))
    assert (run / "geotiff" / "elevation_m.tif").stat().st_size > 0
    assert f"wrote {run / 'next.plan'}" in _layerpilot("plan", "next", str(run), "--max-waypoints", "5")
    home = json.loads((run / "next.plan").read_text())["mission"]["plannedHomePosition"]
    assert home == pytest.approx([frame["lat"], frame["lon"], frame["alt"]], abs=1e-6)


def test_demo_states_its_real_time_factor_and_the_paths_it_wrote(demo) -> None:
    _, run = demo
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["mission_s"] == 10.0 and metrics["wall_s"] > 0
    assert metrics["real_time_factor"] == pytest.approx(metrics["mission_s"] / metrics["wall_s"], rel=0.01)
    md = (run / "report.md").read_text()
    assert f"| real-time factor (mission s per wall s) | {metrics['real_time_factor']:.4g} |" in md
    assert f"| map_server.snapshot | {run / 'map.ot'} |" in md and f"| decide.state | {run / 'survey.json'} |" in md
    assert "runs/default" not in md  # the mission file's paths, which this run did not write
    settings = metrics["settings"]
    assert settings["sim.urls"] == [settings["link.link.url"]] and settings["link.link.url"] != "tcp:127.0.0.1:5760"


def test_study_quick_report_has_every_section_and_plausible_values(tmp_path) -> None:
    out = _layerpilot("study", "--quick", "--duration", "20", "--behaviors", "default,orbit", "--out", str(tmp_path))
    study = tmp_path / "study"
    assert f"report: {study / 'report.html'}" in out
    page = (study / "report.html").read_text()
    for section in ["Table 1", "Standard 3D metrics", "Scoring up to the map", "Runs", "Settings", "Metrics over time",
                    "Flight paths"]:
        assert section in page, section
    assert len(re.findall(r"data:image/png;base64,", page)) >= 8 + 2 * 2  # metric plots + each run's path, layers
    behaviors = json.loads((study / "metrics.json").read_text())["behaviors"]
    assert set(behaviors) == {"view-side", "orbit"}  # default: the mission's own behavior
    for name, entry in behaviors.items():
        series = MetricSeries.read_csv(Path(entry["runs"][0]) / "metrics.csv")
        assert (Path(entry["runs"][0]) / "mission.rrd").stat().st_size > 0, name  # every study run's recording
        mapped = series.column("percent_mapped")
        assert np.all((mapped >= 0) & (mapped <= 100)) and np.all(np.diff(mapped) >= 0) and mapped[-1] > 0, name
        final = entry["final"][0]
        assert 0 < final["recall"] <= 1 and 0 < final["precision"] <= 1 and final["paper_mse"] >= 0, name
