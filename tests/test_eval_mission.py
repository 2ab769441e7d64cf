"""A short seeded mission through the whole loop (real renderer, stereo, map, decision, MAVLink)."""

from __future__ import annotations

import json

import numpy as np

from layerpilot.eval.metrics import MAP_METRICS
from layerpilot.eval.mission import run_mission
from layerpilot.eval.series import MetricSeries
from layerpilot.missionfile import Override, load_mission

SHORT = load_mission("default", [Override("--duration", "evaluation.duration", 20.0),
                                 Override("--step", "evaluation.step_s", 0.1),
                                 Override("--camera", "sim.camera", {"width": 160, "height": 120})])


def test_short_mission_is_deterministic_and_writes_the_run(tmp_path) -> None:
    """Two runs, one with the stages overlapped (the default) and one in the sequential order: the same bytes."""
    a = run_mission(SHORT, tmp_path / "a")
    b = run_mission(SHORT, tmp_path / "b", overlap=False)
    for name in ("metrics.csv", "decisions.jsonl", "map.ot"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    assert a.final == b.final and a.waypoints == b.waypoints >= 2

    series = MetricSeries.read_csv(tmp_path / "a" / "metrics.csv")
    np.testing.assert_allclose(series.column("t"), [0, 10, 20], atol=1e-6)
    mapped = series.column("percent_mapped")
    assert mapped[0] == 0.0 and 0.0 < mapped[1] < mapped[2] < 100.0
    assert 0.0 < a.final["precision"] <= 1.0 and 0.0 < a.final["recall"] <= 1.0
    assert 0.0 <= a.final["avg_time_since_observed"] <= 20.0
    # perfect sensors: the map is aligned by its poses' common offset, 0, so both ways score the same
    # (a map search would take up this 160x120 stereo map's own 1, -1, -2 m; docs/eval.md)
    assert (a.final["offset_x"], a.final["offset_y"], a.final["offset_z"]) == (0.0, 0.0, 0.0)
    assert all(a.final[k] == a.final[f"{k}_absolute"] for k in MAP_METRICS if not np.isnan(a.final[k]))
    for name in ["report.html", "report.md", "metrics.json", "map.ot", "map.bt", "plots/flight_path.png"]:
        assert (tmp_path / "a" / name).stat().st_size > 0, name
    first = json.loads((tmp_path / "a" / "decisions.jsonl").read_text().splitlines()[0])
    assert first["time"] == 0.0 and len(first["waypoint"]) == 3 and "explanation" in first


def test_a_consumer_sensor_mission_is_the_same_whatever_the_take_off_took(tmp_path) -> None:
    """The wall-paced take-off steps the sensors' errors a varying number of times; the mission restarts
    them at its clock's 0, so two runs map the same bytes. The link re-sends its setpoint on the wall clock,
    which moves the vehicle's target by rounding alone: yaws may differ in their last digit."""
    mission = load_mission("consumer", [Override("--duration", "evaluation.duration", 20.0),
                                        Override("--camera", "sim.camera", {"width": 160, "height": 120})])
    run_mission(mission, tmp_path / "a")
    run_mission(mission, tmp_path / "b")
    for name in ("metrics.csv", "map.ot"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    a, b = _records(tmp_path / "a"), _records(tmp_path / "b")
    assert len(a) == len(b) >= 2
    for ra, rb in zip(a, b):
        assert ra["waypoint"] == rb["waypoint"] and abs(ra["yaw"] - rb["yaw"]) < 1e-9, (ra, rb)


def _records(run_dir) -> list[dict]:
    return [json.loads(line) for line in (run_dir / "decisions.jsonl").read_text().splitlines()]


def _behavior(tmp_path, name: str, text: str) -> str:
    path = tmp_path / f"{name}.toml"
    path.write_text('weights = { fringe = 1.0, time = 0.5 }\n' + text)
    return str(path)


def test_the_evaluator_retargets_while_flying_when_the_behavior_opts_in(tmp_path) -> None:
    runs = {}
    for enabled in (False, True):
        behavior = _behavior(tmp_path, f"rt-{enabled}", f"[retarget]\nenabled = {str(enabled).lower()}\n"
                                                          "min_interval = 1.0\nmargin = 0.1\n")
        mission = load_mission("default", [Override("--behavior", "decide.behavior", behavior),
                                           Override("--duration", "evaluation.duration", 40.0),
                                           Override("--step", "evaluation.step_s", 0.1),
                                           Override("--camera", "sim.camera", {"width": 160, "height": 120})])
        run_mission(mission, tmp_path / f"run-{enabled}")
        runs[enabled] = _records(tmp_path / f"run-{enabled}")
    assert not any(r["reason"] == "retarget" for r in runs[False])
    switches = [r for r in runs[True] if r["reason"] == "retarget"]
    assert switches and all(r["retargeted"] for r in switches)
    assert [r["waypoint"] for r in runs[True]] != [r["waypoint"] for r in runs[False]]


def test_the_evaluator_follows_the_weight_schedule(tmp_path) -> None:
    behavior = _behavior(tmp_path, "phases", "[[schedule]]\nafter_time = 15.0\nweights = { distance = 1.0 }\n")
    mission = load_mission("default", [Override("--behavior", "decide.behavior", behavior),
                                       Override("--duration", "evaluation.duration", 40.0),
                                       Override("--step", "evaluation.step_s", 0.1),
                                       Override("--camera", "sim.camera", {"width": 160, "height": 120})])
    run_mission(mission, tmp_path / "run")
    records = _records(tmp_path / "run")
    early = [r["weights"] for r in records if r["time"] < 15.0]
    late = [r["weights"] for r in records if r["time"] >= 15.0]
    assert early and late
    assert all(w == {"fringe": 1.0, "time": 0.5} for w in early) and all(w == {"distance": 1.0} for w in late)
