"""The study's new columns, time to X % of the area and the paired-frame ratio, read off real runs."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from layerpilot.eval.milestones import never_or_spread, paired_ratio, time_to_percent
from layerpilot.eval.series import MetricSeries

ROOT = Path(__file__).resolve().parents[1]


def _series(ts, mapped) -> MetricSeries:
    s = MetricSeries(["percent_mapped"])
    for t, m in zip(ts, mapped):
        s.append(t, {"percent_mapped": m})
    return s


def test_time_to_percent_interpolates_between_samples_and_says_never() -> None:
    s = _series([0, 10, 20, 30], [0.0, 40.0, 60.0, 95.0])
    assert time_to_percent(s, 50) == pytest.approx(15.0)
    assert time_to_percent(s, 80) == pytest.approx(20 + 10 * 20 / 35)
    assert time_to_percent(s, 95) == pytest.approx(30.0)
    assert math.isnan(time_to_percent(s, 96))
    assert paired_ratio({"frames": 601, "clouds": 589}) == pytest.approx(0.98003, abs=1e-5)
    assert never_or_spread([100.0, 120.0]) == "110 ± 14"
    assert never_or_spread([100.0, math.nan]) == "100 (1 of 2 never)" and never_or_spread([math.nan]) == "never"
    with pytest.raises(ValueError, match="percent"):
        time_to_percent(s, 0)


def test_a_study_over_world_seeds_reports_time_to_coverage_and_paired_ratio_from_each_run(tmp_path) -> None:
    """A 20 s lock-step study of view-side over a 40 m area on world 3: the report's numbers are the run's."""
    preset = (ROOT / "config" / "behaviors" / "view-side.toml").read_text()
    small = tmp_path / "small-view.toml"
    small.write_text(preset.replace("radius = 100.0", "radius = 40.0"))
    done = subprocess.run([sys.executable, "-m", "layerpilot.cli", "study", "--quick", "--duration", "20",
                           "--behaviors", str(small), "--world-seeds", "3", "--no-rrd", "--out", str(tmp_path)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600,
                          env={"PYTHONPATH": str(ROOT / "python"), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr[-2000:]
    assert "mean over worlds and seeds:" in done.stdout
    study = json.loads((tmp_path / "study" / "metrics.json").read_text())
    entry = study["behaviors"][str(small)]
    run = Path(entry["runs"][0])
    assert run.name == "small-view-w3-s0" and study["settings"]["sim.world.seed"] == "3"
    assert (run / "metrics.csv").exists() and not (run / "mission.rrd").exists()  # --no-rrd
    settings = json.loads((run / "metrics.json").read_text())["settings"]
    assert settings["sim.world.seed"] == 3
    rows = list(zip(*[np.genfromtxt(run / "metrics.csv", delimiter=",", names=True)[k] for k in ("t", "percent_mapped")]))
    t, mapped = np.array(rows).T
    assert mapped[-1] > 50.0  # the small area is half seen within 20 s, so the column has a number
    i = int(np.argmax(mapped >= 50.0))
    expected = t[i - 1] + (50.0 - mapped[i - 1]) / (mapped[i] - mapped[i - 1]) * (t[i] - t[i - 1])
    got = entry["milestones"][0]
    assert got["time_to_50"] == pytest.approx(expected, abs=1e-9)
    assert got["paired_ratio"] == pytest.approx(settings["clouds"] / settings["frames"]) and got["paired_ratio"] > 0.5
    assert got["retargets"] == settings["retargets"]
    page = (tmp_path / "study" / "report.html").read_text()
    assert "Coverage speed and stereo pairing" in page and f"{expected:.0f}" in page
