"""A fleet in lock-step: several drones, each with its own simulator, MAVLink link and pilot, on one map."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from rerun.chunk import RrdReader

from layerpilot.cli.eval import _run, fleet
from layerpilot.eval.fleet import FleetTracker
from layerpilot.eval.mission import START_SPACING, LockstepMission
from layerpilot.grid import GridGeometry
from layerpilot.missionfile import Override, load_mission

SHORT = load_mission("default", [Override("--duration", "evaluation.duration", 60.0),
                                 Override("--step", "evaluation.step_s", 0.1),
                                 Override("--camera", "sim.camera", {"width": 160, "height": 120})])


def _flown(records: list[dict], vehicles: list[str]) -> list[dict]:
    """The decisions in the order they were taken: by time, and within a tick in the mission's order."""
    return sorted(records, key=lambda r: (r["time"], vehicles.index(r["vehicle"])))


def test_two_drones_share_one_map_keep_their_targets_apart_and_map_more_than_one(tmp_path) -> None:
    one = LockstepMission(SHORT)
    alone = one.run(tmp_path / "one")
    two_drones = fleet(SHORT, 2)
    assert two_drones.vehicles == ["uav1", "uav2"]
    two = LockstepMission(two_drones)
    pair = two.run(tmp_path / "two")
    # the same fleet with its recording: the second drone and its target are drawn beside the first
    recorded = _run(two_drones, tmp_path / "recorded")
    assert recorded.final == pair.final  # the view only watches
    rows = {}
    for chunk in RrdReader(tmp_path / "recorded" / "mission.rrd").stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    assert rows.get("/world/fleet/uav2", 0) >= pair.frames // 2 - 1, sorted(rows)
    assert rows.get("/world/fleet/uav2/target", 0) > 0 and "/world/fleet/uav1" not in rows

    records = [json.loads(line) for line in (tmp_path / "two" / "decisions.jsonl").read_text().splitlines()]
    by_vehicle = {v: [r for r in records if r["vehicle"] == v] for v in two_drones.vehicles}
    assert all(len(rs) >= 2 for rs in by_vehicle.values()), {v: len(rs) for v, rs in by_vehicle.items()}

    # each choice keeps r_e from the other drone's target of that moment (the live decide nodes' rule)
    r_e = two.pipeline.pilots["uav1"].maker.behavior.r_e
    current: dict[str, list[float]] = {}
    for r in _flown(records, two_drones.vehicles):
        other = current.get("uav2" if r["vehicle"] == "uav1" else "uav1")
        if other is not None and r["reason"] != "battery":
            gap = math.dist(r["waypoint"][:2], other[:2])
            assert gap >= r_e - 1e-6, (r, other, gap)
        current[r["vehicle"]] = r["waypoint"]

    # altitude layers: the second drone flies 10 m above the first, so crossing paths pass apart
    layer = two_drones.decide.altitude_layer
    assert {r["waypoint"][2] for r in by_vehicle["uav1"]} == {50.0}
    assert {r["waypoint"][2] for r in by_vehicle["uav2"]} == {50.0 + layer}
    # the fleet's numbers: closest approach over the flight, work done twice, each drone's share
    f = pair.final
    assert 0.0 < f["fleet_min_separation_m"] <= START_SPACING + 1e-6
    separated = f["fleet_min_separation_m"] >= two_drones.link.separation
    assert separated or f["fleet_min_height_gap_near_m"] >= 0.8 * layer, f
    assert 0.0 < f["fleet_duplicate_coverage"] < 1.0
    assert f["seen_uav1"] > 10.0 and f["seen_uav2"] > 10.0
    assert "fleet_min_separation_m" not in alone.final  # one drone: no fleet rows
    # one map, fed by both: more of the area in the same time
    assert f["percent_mapped"] > alone.final["percent_mapped"] + 5.0, (f["percent_mapped"],
                                                                       alone.final["percent_mapped"])
    assert pair.frames == 2 * alone.frames
    json.loads((tmp_path / "two" / "metrics.json").read_text())  # the report is written, fleet keys included
    assert (tmp_path / "two" / "survey-uav2.json").stat().st_size > 0


def test_fleet_tracker_counts_the_closest_approach_and_the_columns_seen_twice() -> None:
    g = GridGeometry(0.0, 0.0, 1.0, 4, 2)
    aoi = np.ones(g.shape, bool)
    aoi[1, 3] = False
    tracker = FleetTracker(g, aoi, ["a", "b", "c"], separation=12.0)
    tracker.positions(0.0, {"a": (0.0, 0.0, 50.0), "b": (30.0, 40.0, 50.0), "c": (100.0, 0.0, 10.0)})
    assert math.isnan(tracker.metrics()["fleet_min_height_gap_near_m"])  # never nearer than 12 m
    tracker.positions(1.0, {"a": (0.0, 0.0, 50.0), "b": (6.0, 8.0, 90.0), "c": (100.0, 0.0, 10.0)})
    tracker.positions(2.0, {"a": (0.0, 0.0, 50.0), "b": (9.0, 8.0, 61.0), "c": (100.0, 0.0, 10.0)})
    assert tracker.min_separation == 10.0 and tracker.closest == (1.0, "a", "b")  # horizontal only
    assert tracker.metrics()["fleet_min_height_gap_near_m"] == 40.0  # at t = 1; at t = 2 12.04 m apart: not near
    tracker.saw("a", np.array([[0.5, 0.5, 3.0], [1.5, 0.5, 3.0], [3.5, 1.5, 0.0], [-1.0, 0.5, 0.0]]), 1.0)
    tracker.saw("b", np.array([[1.2, 0.1, 9.0], [2.5, 1.5, 0.0]]), 2.0)
    m = tracker.metrics()
    # seen in the area: (0,0) (0,1) by a, (0,1) (1,2) by b -> 3 columns, 1 twice; (1,3) is outside it
    assert m["fleet_duplicate_coverage"] == pytest.approx(1 / 3)
    assert m["seen_a"] == pytest.approx(100 * 2 / 7) and m["seen_b"] == pytest.approx(100 * 2 / 7)
    assert m["seen_c"] == 0.0 and m["fleet_min_separation_m"] == 10.0
    early = tracker.metrics(until=1.5)  # before b's cloud: nothing seen twice yet
    assert early["fleet_duplicate_coverage"] == 0.0 and early["seen_b"] == m["seen_b"]
    with pytest.raises(ValueError, match="aoi: shape"):
        FleetTracker(g, np.ones((3, 3), bool), ["a"])


@pytest.mark.parametrize("argv, message", [
    (["demo", "--drones", "0"], "--drones must be in [1, 8], got 0"),
    (["study", "--drones", "2,x"], "expected comma-separated drone counts"),
    (["study", "--drones", "1,1"], "expected distinct drone counts in [1, 8]"),
])
def test_a_bad_fleet_size_is_an_error_naming_the_flag(argv, message) -> None:
    done = subprocess.run([sys.executable, "-m", "layerpilot.cli", *argv], capture_output=True, text=True, timeout=60)
    assert done.returncode != 0 and message in done.stderr, done.stderr
