"""Property tests: waypoints stay in the area of interest and outside r_e; zero weights remove a layer."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from layerpilot.decide import Area, Behavior, DecisionMaker, zone_mask
from layerpilot.grid import GridGeometry
from layerpilot.layers import FeatureLayers

G = GridGeometry(-40.0, -40.0, 1.0, 80, 80)


def _layers(seed: int, observed_fraction: float) -> FeatureLayers:
    rng = np.random.default_rng(seed)
    observed = rng.random(G.shape) < observed_fraction
    named = {k: np.where(observed, rng.random(G.shape), 0).astype(np.float32) for k in ("a", "b")}
    return FeatureLayers(G, named, observed, np.zeros(G.shape, np.float32), np.zeros((*G.shape, 3), np.uint8))


coord = st.floats(-60.0, 60.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    fraction=st.sampled_from([0.0, 0.01, 0.5, 1.0]),
    position=st.tuples(coord, coord),
    home=st.tuples(st.floats(-20, 20), st.floats(-20, 20)),
    radius=st.floats(3.0, 50.0),
    r_e=st.floats(0.0, 20.0),
    polygon=st.booleans(),
    ticks=st.integers(1, 4),
)
def test_waypoints_stay_in_the_area_and_outside_r_e(seed, fraction, position, home, radius, r_e, polygon, ticks) -> None:
    area = Area(radius=radius)
    if polygon:
        hx, hy = home
        area = Area(shape="polygon", polygon=[(hx - radius, hy - 2), (hx + radius, hy - 3), (hx, hy + radius)])
    behavior = Behavior(weights={"a": 1.0, "b": 0.5}, r_e=r_e, r_i=r_e + 40.0, area=area, n=0.2)
    zone = zone_mask(area, G, home)
    if not zone.any():
        return
    dm = DecisionMaker(behavior, home=home, seed=seed)
    layers = _layers(seed, fraction)
    x, y = G.cell_centers()
    for t in range(ticks):
        in_ring = (zone > 0) & (np.hypot(x - position[0], y - position[1]) >= r_e)
        d = dm.decide(layers, (*position, 40.0), float(t))
        r, c = G.cell_of(d.waypoint[0], d.waypoint[1])
        assert zone[r, c] == 1.0, d
        if in_ring.any():  # outside r_e whenever some area cell is (distances are float32: 1 mm)
            assert np.hypot(d.waypoint[0] - position[0], d.waypoint[1] - position[1]) >= r_e - 1e-3, d
        assert d.score >= 0 and (d.fallback is None) == (d.score > 0)
        position = d.waypoint[:2]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), weight=st.floats(0.1, 2.0), position=st.tuples(coord, coord))
def test_zero_weight_removes_a_layers_influence(seed, weight, position) -> None:
    layers = _layers(seed, 0.7)
    rng = np.random.default_rng(seed + 1)
    other = FeatureLayers(G, {"a": layers["a"], "b": rng.random(G.shape).astype(np.float32)}, layers.observed,
                     layers.elevation_m, layers.rgb)
    behavior = Behavior(weights={"a": weight, "b": 0.0}, r_e=5.0, r_i=50.0, area=Area(radius=35.0))
    one = DecisionMaker(behavior, seed=seed).decide(layers, position, 0.0, intermediates=True)
    two = DecisionMaker(behavior, seed=seed).decide(other, position, 0.0, intermediates=True)
    assert one.waypoint == two.waypoint and one.score == two.score
    np.testing.assert_array_equal(one.intermediates["A3"], two.intermediates["A3"])
    assert "b" not in one.contributions
