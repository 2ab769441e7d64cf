"""Each step of the decision on small hand-computed grids: A0, Z, P, H, noise, selection, fallback."""

from __future__ import annotations

import json

import numpy as np
import pytest

from layerpilot.decide import (
    Area,
    Behavior,
    DecisionMaker,
    PathHistory,
    area_geometry,
    distance_preference,
    zone_mask,
)
from layerpilot.grid import GridGeometry
from layerpilot.layers import FeatureLayers


def layer_set(g: GridGeometry, observed: np.ndarray | None = None, **layers: np.ndarray) -> FeatureLayers:
    h, w = g.shape
    obs = np.ones((h, w), bool) if observed is None else observed
    return FeatureLayers(g, {k: v.astype(np.float32) for k, v in layers.items()}, obs,
                    np.zeros((h, w), np.float32), np.zeros((h, w, 3), np.uint8))


def test_distance_ring() -> None:
    d = np.array([0.0, 5.0, 9.99, 10.0, 32.5, 55.0, 100.0, 150.0], np.float32)
    np.testing.assert_allclose(distance_preference(d, 10.0, 100.0), [0, 0, 0, 1, 0.75, 0.5, 0, 0], atol=1e-6)


def test_zone_circle_and_polygon() -> None:
    g = GridGeometry(0.0, 0.0, 1.0, 5, 4)
    z = zone_mask(Area(radius=1.6), g, home=(2.5, 1.5))  # centre of cell (1, 2)
    expected = np.zeros((4, 5), np.float32)
    expected[0:3, 1:4] = 1  # 3x3 block (corners at sqrt(2) <= 1.6)
    np.testing.assert_array_equal(z, expected)
    tri = Area(shape="polygon", polygon=[(0.0, 0.0), (5.0, 0.0), (0.0, 4.0)])
    z = zone_mask(tri, g, home=(0.0, 0.0))
    x, y = g.cell_centers()
    np.testing.assert_array_equal(z, (x / 5 + y / 4 < 1).astype(np.float32))


def test_path_history_decay_over_ticks() -> None:
    g = GridGeometry(0.0, 0.0, 1.0, 6, 1)
    h = PathHistory(r_e=1.0, n=0.25)
    xs = (np.arange(6) + 0.5)[None, :]
    np.testing.assert_array_equal(h.tick(g, np.abs(xs - 0.5)), [[0, 1, 1, 1, 1, 1]])
    np.testing.assert_array_equal(h.tick(g, np.abs(xs - 2.5)), [[0.25, 1, 0, 1, 1, 1]])
    np.testing.assert_array_equal(h.tick(g, np.abs(xs - 4.5)), [[0.5, 1, 0.25, 1, 0, 1]])
    for _ in range(3):
        values = h.tick(g, np.full((1, 6), 9.0))
    np.testing.assert_array_equal(values, [[1, 1, 1, 1, 0.75, 1]])
    assert h.ticks == 6
    # the grid moves two cells east: shared cells keep their history, new ones start at 1
    moved = GridGeometry(2.0, 0.0, 1.0, 6, 1)
    np.testing.assert_array_equal(h.on(moved), [[1, 1, 0.75, 1, 1, 1]])


def test_each_stage_by_hand() -> None:
    # 1 x 8 strip, drone at x = 0.5; r_e = 2, r_i = 7; area: circle radius 5.1 around x = 0.5
    g = GridGeometry(0.0, 0.0, 1.0, 8, 1)
    a = np.array([[0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.0, 1.0]])
    b = np.array([[1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0]])
    behavior = Behavior(weights={"a": 0.5, "b": 0.25}, r_e=2.0, r_i=7.0, n=0.1, noise=0.0,
                        area=Area(radius=5.1), altitude=42.0)
    dm = DecisionMaker(behavior, home=(0.5, 0.5))
    d = dm.decide(layer_set(g, a=a, b=b), (0.5, 0.5, 30.0), 0.0, intermediates=True)
    im = d.intermediates
    a0 = 0.5 * a + 0.25 * b
    np.testing.assert_allclose(im["A0"], a0, atol=1e-6)
    np.testing.assert_array_equal(im["Z"], [[1, 1, 1, 1, 1, 1, 0, 0]])
    p = np.array([[0, 0, 1, 0.8, 0.6, 0.4, 0.2, 0]])
    np.testing.assert_allclose(im["P"], p, atol=1e-6)
    np.testing.assert_array_equal(im["H"], [[0, 0, 1, 1, 1, 1, 1, 1]])
    a3 = a0 * im["Z"] * p * im["H"]
    np.testing.assert_allclose(im["A3"], a3, atol=1e-6)
    # A3 = [0, 0, .45, .44, .24, .2, 0, 0]: cell 2 wins
    assert d.cell == (0, 2) and d.waypoint == (2.5, 0.5, 42.0)
    assert d.score == pytest.approx(0.45) and d.aggregate == pytest.approx(0.45)
    assert d.contributions == pytest.approx({"a": 0.2, "b": 0.25})
    assert (d.zone, d.preference, d.history) == (1.0, 1.0, 1.0)
    assert d.fallback is None and d.coverage == 1.0
    # runner-up: best cell at least r_e = 2 m from the winner -> cell 4 (cell 3 is too close)
    assert d.runner_up.cell == (0, 4) and d.runner_up.score == pytest.approx(0.24)
    assert "A0 0.4500" in d.explain()
    record = json.loads(json.dumps(d.to_dict()))  # decisions.jsonl / the bus
    assert record["waypoint"] == [2.5, 0.5, 42.0] and record["runner_up"]["cell"] == [0, 4]
    assert "intermediates" not in record


def test_noise_breaks_ties_reproducibly() -> None:
    g = GridGeometry(-50.0, -50.0, 1.0, 100, 100)
    flat = layer_set(g, f=np.ones(g.shape))
    behavior = Behavior(weights={"f": 1.0}, r_e=10.0, r_i=11.0, noise=1e-3)
    picks = [DecisionMaker(behavior, seed=s).decide(flat, (0.0, 0.0), 0.0).cell for s in (1, 1, 2, 3)]
    assert picks[0] == picks[1]  # same seed, same choice
    assert len(set(picks[1:])) > 1  # other seeds pick other cells of the tie
    for cell in picks:
        x, y = g.cell_center(*cell)
        assert 10.0 <= np.hypot(x, y) < 11.0


def test_fallback_wander_then_approach() -> None:
    behavior = Behavior(weights={"fringe": 1.0}, r_e=10.0, r_i=60.0, n=0.0)
    g = area_geometry(behavior.area, (0.0, 0.0))
    empty = layer_set(g, np.zeros(g.shape, bool), fringe=np.zeros(g.shape))
    dm = DecisionMaker(behavior)
    d = dm.decide(empty, (0.0, 0.0, 50.0), 0.0)
    x, y, _ = d.waypoint
    assert d.fallback == "wander" and d.score == 0.0 and d.aggregate == 0.0
    assert 10.0 <= np.hypot(x, y) <= 60.0 and d.preference > 0
    # drone far outside the area (beyond r_i of every area cell): fly to the nearest area cell
    far = DecisionMaker(behavior).decide(empty, (250.0, 0.0, 50.0), 0.0)
    assert far.fallback == "approach"
    assert far.waypoint[0] == pytest.approx(99.5) and abs(far.waypoint[1]) <= 1.0
    with pytest.raises(ValueError, match="geometry: the grid .* does not overlap the area"):
        DecisionMaker(behavior).decide(layer_set(GridGeometry(500.0, 500.0, 1.0, 4, 4), fringe=np.ones((4, 4))),
                                       (0.0, 0.0), 0.0)


def test_avoid_keeps_away_from_other_targets() -> None:
    g = GridGeometry(-50.0, -50.0, 1.0, 100, 100)
    x, y = g.cell_centers()
    peak = np.exp(-((x - 30) ** 2 + y**2) / 200.0)
    behavior = Behavior(weights={"f": 1.0}, r_e=10.0, r_i=100.0)
    alone = DecisionMaker(behavior).decide(layer_set(g, f=peak), (0.0, 0.0), 0.0)
    assert np.hypot(alone.waypoint[0] - 30, alone.waypoint[1]) < 3
    shared = DecisionMaker(behavior).decide(layer_set(g, f=peak), (0.0, 0.0), 0.0, avoid=[(30.0, 0.0)])
    assert np.hypot(shared.waypoint[0] - 30, shared.waypoint[1]) >= 10.0


def test_bad_inputs_name_the_argument() -> None:
    g = GridGeometry(-50.0, -50.0, 1.0, 100, 100)
    dm = DecisionMaker(Behavior(weights={"fringe": 1.0, "time": 0.5}))
    with pytest.raises(ValueError, match="position"):
        dm.decide(layer_set(g, fringe=np.ones(g.shape), time=np.ones(g.shape)), (np.nan, 0.0), 0.0)
    with pytest.raises(ValueError, match="layers: behavior weights 'time'"):
        dm.decide(layer_set(g, fringe=np.ones(g.shape)), (0.0, 0.0), 0.0)
