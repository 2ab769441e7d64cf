"""`layerpilot demo` and `layerpilot study --quick` as a user runs them (real processes, real missions)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from layerpilot.eval.series import MetricSeries

ROOT = Path(__file__).resolve().parents[1]


def _layerpilot(*args: str) -> str:
    done = subprocess.run([sys.executable, "-m", "layerpilot.cli", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=600, env={"PYTHONPATH": str(ROOT / "python"), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_demo_prints_metrics_and_report_path(tmp_path) -> None:
    out = _layerpilot("demo", "--duration", "10", "--camera", "160x120", "--out", str(tmp_path), "--name", "d")
    assert "area mapped (%)" in out and "3D F-score" in out
    assert f"report: {tmp_path / 'd' / 'report.html'}" in out
    final = json.loads((tmp_path / "d" / "metrics.json").read_text())["final"]
    assert 0.0 < final["percent_mapped"] < 100.0


def test_study_quick_report_has_every_section_and_plausible_values(tmp_path) -> None:
    out = _layerpilot("study", "--quick", "--duration", "20", "--behaviors", "balanced,orbit", "--out", str(tmp_path))
    study = tmp_path / "study"
    assert f"report: {study / 'report.html'}" in out
    page = (study / "report.html").read_text()
    for section in ["Table 1", "Standard 3D metrics", "Scoring up to the map", "Runs", "Settings", "Metrics over time",
                    "Flight paths"]:
        assert section in page, section
    assert len(re.findall(r"data:image/png;base64,", page)) >= 8 + 2 * 2  # metric plots + each run's path, layers
    behaviors = json.loads((study / "metrics.json").read_text())["behaviors"]
    assert set(behaviors) == {"balanced", "orbit"}
    for name, entry in behaviors.items():
        series = MetricSeries.read_csv(Path(entry["runs"][0]) / "metrics.csv")
        assert (Path(entry["runs"][0]) / "mission.rrd").stat().st_size > 0, name  # every study run's recording
        mapped = series.column("percent_mapped")
        assert np.all((mapped >= 0) & (mapped <= 100)) and np.all(np.diff(mapped) >= 0) and mapped[-1] > 0, name
        final = entry["final"][0]
        assert 0 < final["recall"] <= 1 and 0 < final["precision"] <= 1 and final["paper_mse"] >= 0, name
