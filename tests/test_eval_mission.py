"""A short seeded mission through the whole loop (real renderer, stereo, map, decision, MAVLink)."""

from __future__ import annotations

import json

import numpy as np

from layerpilot.eval.mission import MissionConfig, run_mission
from layerpilot.eval.series import MetricSeries

SHORT = MissionConfig(duration=20.0, camera_width=160, camera_height=120, frame_rate_hz=1.0, step_s=0.1)


def test_short_mission_is_deterministic_and_writes_the_run(tmp_path) -> None:
    a = run_mission(SHORT, tmp_path / "a")
    b = run_mission(SHORT, tmp_path / "b")
    assert (tmp_path / "a" / "metrics.csv").read_text() == (tmp_path / "b" / "metrics.csv").read_text()
    assert (tmp_path / "a" / "decisions.jsonl").read_text() == (tmp_path / "b" / "decisions.jsonl").read_text()
    assert a.final == b.final and a.waypoints == b.waypoints >= 2

    series = MetricSeries.read_csv(tmp_path / "a" / "metrics.csv")
    np.testing.assert_allclose(series.column("t"), [0, 10, 20], atol=1e-6)
    mapped = series.column("percent_mapped")
    assert mapped[0] == 0.0 and 0.0 < mapped[1] < mapped[2] < 100.0
    assert 0.0 < a.final["precision"] <= 1.0 and 0.0 < a.final["recall"] <= 1.0
    assert 0.0 <= a.final["avg_time_since_observed"] <= 20.0
    for name in ["report.html", "report.md", "metrics.json", "map.ot", "map.bt", "plots/flight_path.png"]:
        assert (tmp_path / "a" / name).stat().st_size > 0, name
    first = json.loads((tmp_path / "a" / "decisions.jsonl").read_text().splitlines()[0])
    assert first["time"] == 0.0 and len(first["waypoint"]) == 3 and "explanation" in first
