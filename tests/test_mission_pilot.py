"""The pilot step object on its own: arrival, patterns, retargeting and weight schedules."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from layerpilot.decide.behavior import behavior_from_dict
from layerpilot.map import VoxelMap
from layerpilot.mission.build import build_pilot
from layerpilot.missionfile import Mission
from layerpilot.mission.pilot import Pilot, PilotConfig
from layerpilot.sim.simulator import SimConfig


def ground_columns(half: float, stamp: float):
    """Column layers of a 256 m window where a (2 half) m square of ground around home was seen at ``stamp``."""
    m = VoxelMap(1.0)
    xs, ys = np.meshgrid(np.arange(-half, half) + 0.5, np.arange(-half, half) + 0.5)
    pts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1).astype(np.float32)
    m.insert(pts, np.array([0.0, 0.0, 30.0]), stamp=stamp)
    return m.column_layers(-128, -128, 256, 256)


def fringe_behavior(**extra) -> dict:
    return {"name": "fringe-test", "weights": {"fringe": 1.0}, "noise": 0.0, **extra}


def test_arrival_is_horizontal_and_counts_each_target_once() -> None:
    pilot = Pilot(PilotConfig(arrival_radius=3.0), behavior_from_dict(fringe_behavior()))
    cols = ground_columns(20, 1.0)
    first = pilot.step((0.0, 0.0, 50.0), 1.0, cols)
    assert first is not None and first.seq == 1 and first.reason == "start"
    tx, ty, tz = first.position
    assert 10.0 <= np.hypot(tx, ty) <= 100.0 and tz == 50.0
    assert pilot.step((0.0, 0.0, 50.0), 2.0, cols) is None  # flying: nothing new
    # 2.9 m away horizontally and 20 m below: arrived (the altitude is the autopilot's job)
    second = pilot.step((tx + 2.9, ty, 30.0), 3.0, cols)
    assert second is not None and second.reason == "reached" and pilot.reached == 1
    assert pilot.step((tx + 2.9, ty, 30.0), 3.1, cols) is None or pilot.reached == 1


def test_no_layers_no_decision_but_a_pattern_needs_none() -> None:
    pilot = Pilot(PilotConfig(), behavior_from_dict(fringe_behavior()))
    assert pilot.step((0.0, 0.0, 50.0), 0.0, None) is None
    mission = dataclasses.replace(Mission(), decide=PilotConfig(behavior="orbit"))
    orbit = build_pilot(mission.core)
    seen = []
    position = (0.0, 0.0, 50.0)
    for k in range(2 * len(orbit.pattern)):
        c = orbit.step(position, float(k), None)
        assert c is not None and c.decision is None
        seen.append(c.position)
        position = c.position  # arrive at once
    assert seen[: len(orbit.pattern)] == seen[len(orbit.pattern):]  # a patrol: the loop starts over
    assert all(abs(np.hypot(x, y) - 100.0) < 1e-6 for x, y, _ in seen)


def test_lawnmower_flies_at_the_survey_speed_of_the_missions_camera() -> None:
    def pilot(rate: float) -> Pilot:
        return build_pilot(dataclasses.replace(Mission(), decide=PilotConfig(behavior="lawnmower"),
                                             sim=SimConfig(frame_rate_hz=rate)).core)

    slow, fast = pilot(1.0), pilot(2.0)
    assert fast.cruise_speed == pytest.approx(2 * slow.cruise_speed) and slow.cruise_speed > 0
    assert slow.step((0.0, 0.0, 50.0), 0.0, None).speed == slow.cruise_speed


def test_retargeting_switches_while_flying_only_when_the_behavior_opts_in() -> None:
    near, wide = ground_columns(20, 1.0), ground_columns(60, 20.0)
    results = {}
    for enabled in (False, True):
        behavior = behavior_from_dict(fringe_behavior(retarget={"enabled": enabled, "min_interval": 0.0}))
        pilot = Pilot(PilotConfig(), behavior)
        first = pilot.step((0.0, 0.0, 50.0), 1.0, near)
        # halfway there the map has grown past the target: its frontier is gone
        halfway = (first.position[0] / 2, first.position[1] / 2, 50.0)
        results[enabled] = pilot.step(halfway, 20.0, wide)
        assert pilot.step(halfway, 20.5, wide) is None  # once per new layer set
    assert results[False] is None
    switched = results[True]
    assert switched is not None and switched.reason == "retarget" and switched.decision.retargeted
    assert switched.seq == 2 and np.hypot(*switched.position[:2]) > 55.0  # the new frontier


def test_weight_schedule_switches_on_coverage() -> None:
    behavior = behavior_from_dict({"name": "phases", "weights": {"fringe": 1.0}, "noise": 0.0,
                                   "schedule": [{"after_coverage": 0.5, "weights": {"time": 1.0}}]})
    pilot = Pilot(PilotConfig(), behavior)
    first = pilot.step((0.0, 0.0, 50.0), 1.0, ground_columns(20, 1.0))
    assert first.decision.weights == {"fringe": 1.0}
    second = pilot.step(first.position, 50.0, ground_columns(100, 40.0))  # the whole area seen
    assert second.decision.weights == {"time": 1.0}


@pytest.mark.parametrize("radius", [0.0, -1.0, float("nan")])
def test_bad_arrival_radius_is_refused_by_name(radius) -> None:
    with pytest.raises(ValueError, match="decide.arrival_radius"):
        PilotConfig(arrival_radius=radius)


def test_a_drone_without_priority_chooses_again_when_another_takes_its_target() -> None:
    pilot = Pilot(PilotConfig(), behavior_from_dict(fringe_behavior()))
    cols = ground_columns(20, 1.0)
    first = pilot.step((0.0, 0.0, 50.0), 1.0, cols)
    near = (first.position[0] + 3.0, first.position[1])
    assert pilot.step((0.0, 0.0, 50.0), 1.5, cols, avoid=[near]) is None  # no priority: nothing to do
    again = pilot.step((0.0, 0.0, 50.0), 2.0, cols, avoid=[near], yield_to=[near])
    assert again is not None and again.reason == "conflict"
    assert np.hypot(again.position[0] - near[0], again.position[1] - near[1]) >= pilot.behavior.r_e


def test_an_arrival_is_counted_once_while_the_next_choice_waits_for_layers() -> None:
    pilot = Pilot(PilotConfig(), behavior_from_dict(fringe_behavior()))
    first = pilot.step((0.0, 0.0, 50.0), 1.0, ground_columns(20, 1.0))
    for t in (2.0, 2.1, 2.2):  # arrived, but the layer set was dropped (e.g. it failed to decode)
        assert pilot.step(first.position, t, None) is None
    assert pilot.reached == 1
    nxt = pilot.step(first.position, 3.0, ground_columns(20, 2.0))
    assert nxt is not None and nxt.reason == "reached" and pilot.reached == 1
