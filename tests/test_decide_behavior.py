"""Behavior files: presets load, bad keys and values are errors that name the key; schedules."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from layerpilot.config import ConfigError
from layerpilot.decide import Behavior, SchedulePhase, WeightSchedule, behavior_from_dict, load_behavior, preset_names

PRESETS = {
    "balanced": {"fringe": 0.3, "time": 0.3, "distance": 0.3},
    "exploration": {"fringe": 1.0, "time": 0.0, "distance": 0.0},
    "time": {"fringe": 0.0, "time": 1.0, "distance": 0.0},
    "distance": {"fringe": 0.0, "time": 0.0, "distance": 1.0},
}


def test_presets() -> None:
    assert set(PRESETS) <= set(preset_names())
    for name, weights in PRESETS.items():
        b = load_behavior(name)
        assert b.name == name and b.weights == weights
        assert (b.n, b.noise, b.altitude) == (0.01, 0.001, 50.0)
        assert b.area.shape == "circle" and b.area.radius == 100.0
    staged = load_behavior("explore-then-patrol")
    assert staged.schedule[0].after_coverage == 0.85 and staged.schedule[0].weights == {"time": 1.0}
    for name in [*PRESETS, "explore-then-patrol"]:  # issue 15: stereo-aware flight, footprint hops, retargeting
        b = load_behavior(name)
        assert (b.flight.heading, b.flight.speed, b.flight.hops) == ("side", "survey", "footprint") and b.retarget.enabled


def test_metres_in_the_file_win_over_footprint_hops() -> None:
    def hops(**keys: object) -> str:
        return behavior_from_dict({"weights": {"fringe": 1.0}, **keys}).flight.hops

    assert hops() == "footprint" and hops(flight={"heading": "side"}) == "footprint"
    assert hops(r_e=12.0) == "fixed" and hops(r_i=80.0) == "fixed" and hops(flight={"hops": "fixed"}) == "fixed"
    explicit = behavior_from_dict({"weights": {"fringe": 1.0}, "r_e": 12.0, "r_i": 80.0})
    assert (explicit.r_e, explicit.r_i) == (12.0, 80.0)
    assert Behavior(weights={"fringe": 1.0}).flight.hops == "fixed"  # built in code: the paper's 10 m / 100 m


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"weights": {"fringe": 1.0}, "r_e_typo": 3.0}, r"unknown key\(s\) behavior.r_e_typo"),
        ({"weights": {"fringe": "lots"}}, r"behavior.weights.fringe: expected a number"),
        ({"weights": {"fringe": -1.0}}, r"behavior: weights.fringe = -1.0 must be >= 0"),
        ({"weights": {"fringe": 0.0}}, r"behavior: weights: at least one weight must be > 0"),
        ({"weights": {"frinje": 1.0}}, r"behavior.weights.frinje: no layer named 'frinje'"),
        ({"weights": {"fringe": 1.0}, "r_i": 5.0}, r"r_i = 5.0 must be > r_e = 10.0"),
        ({"weights": {"fringe": 1.0}, "n": 2.0}, r"n = 2.0 is out of range"),
        ({"weights": {"fringe": 1.0}, "noise": 0.5}, r"noise = 0.5 is out of range"),
        ({"weights": {"fringe": 1.0}, "area": {"radius": -5.0}}, r"behavior.area: radius = -5.0 must be > 0"),
        ({"weights": {"fringe": 1.0}, "area": {"shape": "square"}}, r"behavior.area.shape: expected one of"),
        ({"weights": {"fringe": 1.0}, "area": {"shape": "polygon", "polygon": [[0, 0], [1, 1]]}},
         r"behavior.area: polygon: a polygon area needs at least 3"),
        ({"weights": {"fringe": 1.0}, "schedule": [{"weights": {"time": 1.0}}]},
         r"behavior.schedule\[0\]: give exactly one of after_time, after_coverage"),
        ({"weights": {"fringe": 1.0}, "schedule": [{"after_time": 5.0, "weights": {"tim": 1.0}}]},
         r"behavior.schedule\[0\].weights.tim: no layer named"),
        ({"weights": {"fringe": 1.0}, "terrain": {"min_altitude": 90.0, "max_altitude": 30.0}},
         r"behavior.terrain: min_altitude = 90.0 must be <= max_altitude"),
        ({"weights": {"fringe": 1.0}, "retarget": {"margin": -0.1}}, r"behavior.retarget: margin = -0.1 must be >= 0"),
        ({"weights": {"fringe": 1.0}, "layers": {"fringe_closing": 99}}, r"behavior.layers: fringe_closing = 99"),
        ({"weights": {"fringe": 1.0}, "plugins": ["missing_file.py"]}, r"behavior.plugins: no such file"),
        ({"r_e": 3.0}, r"behavior: .*weights"),
    ],
)
def test_bad_behaviors_name_the_key(data: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        behavior_from_dict(data)


def test_load_behavior_errors_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text("r_e = 10.0\nr_i = 100.0\n[weights]\nfringe = 1.0\n[area]\nradius = 0.0\n")
    with pytest.raises(ConfigError, match=r"mine.toml: behavior.area: radius = 0.0 must be > 0"):
        load_behavior(path)
    with pytest.raises(ConfigError, match="not a file and not a preset"):
        load_behavior("no-such-preset")


def test_schedule_phases_latch_in_order() -> None:
    b = Behavior(
        weights={"fringe": 1.0},
        schedule=[SchedulePhase({"time": 1.0}, after_coverage=0.85), SchedulePhase({"distance": 1.0}, after_time=600.0)],
    )
    s = WeightSchedule(b)
    assert s.weights(0.0, 0.2) == {"fringe": 1.0}
    assert s.weights(100.0, 0.84) == {"fringe": 1.0}
    assert s.weights(200.0, 0.85) == {"time": 1.0}
    assert s.weights(300.0, 0.5) == {"time": 1.0}  # coverage dipped: the phase stays
    assert s.weights(600.0, 0.5) == {"distance": 1.0}
    # a time phase after a coverage phase waits for the coverage phase first (file order)
    s = WeightSchedule(b)
    assert s.weights(700.0, 0.1) == {"fringe": 1.0}
    assert s.weights(701.0, 0.9) == {"distance": 1.0}


def test_schedule_switches_the_decision(tmp_path: Path) -> None:
    from layerpilot.decide import DecisionMaker
    from layerpilot.grid import GridGeometry
    from layerpilot.layers import FeatureLayers

    g = GridGeometry(-60.0, -60.0, 1.0, 120, 120)
    x, y = g.cell_centers()
    east = np.exp(-((x - 40) ** 2 + y**2) / 50).astype(np.float32)
    west = np.exp(-((x + 40) ** 2 + y**2) / 50).astype(np.float32)
    observed = np.zeros(g.shape, bool)
    layers = lambda obs: FeatureLayers(g, {"fringe": east, "time": west}, obs, np.zeros(g.shape, np.float32),  # noqa: E731
                                  np.zeros((*g.shape, 3), np.uint8))
    b = load_behavior("explore-then-patrol")
    dm = DecisionMaker(b)
    first = dm.decide(layers(observed), (0.0, 0.0), 0.0)
    assert first.waypoint[0] > 30 and first.weights == {"fringe": 1.0} and first.coverage == 0.0
    observed[:] = True
    second = dm.decide(layers(observed), (0.0, 0.0), 10.0)
    assert second.waypoint[0] < -30 and second.weights == {"time": 1.0} and second.coverage == 1.0


def test_presets_and_missions_are_installed_with_the_package():
    """A wheel has no checkout: the build installs config/ beside the C++ module, where shipped_config looks."""
    import filecmp

    from layerpilot import _core

    checkout = Path(__file__).resolve().parents[1] / "config"
    installed = Path(_core.__file__).resolve().parent / "config"
    for kind in ("behaviors", "missions"):
        names = sorted(p.name for p in (checkout / kind).iterdir())
        assert names and sorted(p.name for p in (installed / kind).iterdir()) == names
        match, mismatch, errors = filecmp.cmpfiles(checkout / kind, installed / kind, names, shallow=False)
        assert (mismatch, errors) == ([], [])
