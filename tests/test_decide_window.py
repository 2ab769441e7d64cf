"""The windowed decision (layers and terms only within r_i of the drone) against the whole-grid one.

Over sequences of random map updates (areas seen, re-seen, lost again; the drone moving,
sometimes far outside the area), the pilot's windowed path must choose exactly what the
whole-grid computation chooses, with the same explanation, and its layers must equal the
whole grid's on the window.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from layerpilot.decide import Area, Behavior, DecisionMaker, PathHistory
from layerpilot.grid import GridGeometry, GridWindow
from layerpilot.layers import LayerContext, LayerOptions, compute_layers
from layerpilot.layers.features import fringe
from layerpilot.map.columns import ColumnLayers
from layerpilot.mission.pilot import Pilot, PilotConfig

G = GridGeometry(-36.0, -36.0, 1.0, 72, 72)
NAMES = ["fringe", "time", "distance", "elevation"]


def _update(cols: ColumnLayers, rng: np.random.Generator, now: float) -> None:
    """One map update: a disc of columns seen now (with small holes), sometimes a disc lost again."""
    x, y = G.cell_centers()
    cx, cy, r = rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(3, 25)
    disc = np.hypot(x - cx, y - cy) < r
    seen = disc & (rng.random(G.shape) > 0.04)
    cols.observed[seen] = True
    cols.last_seen[seen] = now
    cols.elevation[seen] = rng.uniform(0, 30, int(seen.sum())).astype(np.float32)
    cols.min_distance[seen] = np.minimum(cols.min_distance[seen], rng.uniform(5, 150)).astype(np.float32)
    if rng.random() < 0.3:  # occupancy flips: a patch is unobserved again
        lost = np.hypot(x - rng.uniform(-30, 30), y - rng.uniform(-30, 30)) < rng.uniform(1, 6)
        cols.observed[lost] = False
        cols.last_seen[lost] = np.nan
        cols.elevation[lost] = np.nan
        cols.min_distance[lost] = np.inf


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**16), closing=st.sampled_from([0, 3, 5]), r_i=st.floats(8.0, 30.0),
       retarget=st.booleans())
def test_windowed_pilot_decides_exactly_as_the_whole_grid(seed: int, closing: int, r_i: float, retarget: bool) -> None:
    rng = np.random.default_rng(seed)
    behavior = Behavior(weights={"fringe": 0.4, "time": 0.3, "distance": 0.2, "elevation": 0.1}, r_e=3.0, r_i=r_i,
                        n=0.2, area=Area(radius=30.0), layers=LayerOptions(fringe_closing=closing))
    behavior = dataclasses.replace(behavior, retarget=dataclasses.replace(behavior.retarget, enabled=retarget,
                                                                          min_interval=0.0))
    pilot = Pilot(PilotConfig(), behavior, seed=seed)
    whole = DecisionMaker(behavior, seed=seed)
    cols = ColumnLayers.empty(G)
    position = (0.0, 0.0, 30.0)
    approached = 0
    for tick in range(8):
        now = 10.0 * (tick + 1)
        _update(cols, rng, now)
        if tick == 5:
            position = (300.0, -250.0, 30.0)  # far outside the area: the approach fallback, beyond r_i
        avoid = [tuple(rng.uniform(-30, 30, 2))] if tick % 3 == 1 else []
        context = LayerContext(now=now, position=position, options=behavior.layers)
        full = compute_layers(cols, context, NAMES)
        window = pilot.maker.window(G, position)
        part = compute_layers(cols, context, NAMES, window=window)
        for name in NAMES:
            np.testing.assert_allclose(part[name], full[name][window.slices], atol=1e-6, err_msg=name)
        if retarget and whole.target is not None:
            moved = (0.5 * (position[0] + whole.target.waypoint[0]), 0.5 * (position[1] + whole.target.waypoint[1]), 30.0)
            want = whole.reconsider(full, moved, now - 5.0)
            got = pilot.maker.reconsider(compute_layers(cols, context, NAMES, window=pilot.maker.window(G, moved)),
                                         moved, now - 5.0)
            assert (got is None) == (want is None)
            if want is not None:
                assert got.to_dict() == want.to_dict()
        pilot.target = None  # a decision is due now
        command = pilot.step(position, now, cols, avoid=avoid)
        want = whole.decide(full, position, now, avoid=avoid)
        assert command.decision.to_dict() == want.to_dict(), (tick, command.decision.explain(), want.explain())
        np.testing.assert_array_equal(pilot.maker.history.values, whole.history.values)
        approached += want.fallback == "approach"
        position = want.waypoint
    assert approached >= 1  # the far position made the maker look beyond its window


def _fresh_fringe(observed: np.ndarray, closing: int) -> np.ndarray:
    """The fringe from scratch: one whole-grid closing and OpenCV distance transform (the oracle)."""
    mask = observed.view(np.uint8)
    if closing > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (closing, closing)))
    if mask.all() or not mask.any():
        return np.zeros(mask.shape, np.float32)
    with np.errstate(divide="ignore"):
        out = 1.0 / cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    out[out > 0.7] = 1.0
    out[mask == 0] = 0.0
    return out


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**16), holes=st.sampled_from([0.0005, 0.01, 0.2]), closing=st.sampled_from([0, 2, 3, 7]),
       corner=st.tuples(st.integers(0, 90), st.integers(0, 60)), size=st.tuples(st.integers(0, 40), st.integers(1, 50)),
       width=st.sampled_from([90, 96]))
def test_incremental_fringe_equals_a_fresh_transform(seed: int, holes: float, closing: int, corner, size,
                                                     width: int) -> None:
    """A mask changed patch by patch (seen, lost, seen again; few holes: deep interiors whose
    distances reach far), the kept distances against a fresh whole-grid transform each time.
    A width of 96 compares the masks 8 cells at a time."""
    rng = np.random.default_rng(seed)
    observed = rng.random((100, width)) > holes
    window = GridWindow(corner[0], min(corner[0] + size[0], 100), corner[1], min(corner[1] + size[1], width))
    for step in range(6):
        r, c, k = int(rng.integers(0, 100)), int(rng.integers(0, width)), int(rng.integers(1, 30))
        observed[r:r + k, c:c + k] = rng.random(observed[r:r + k, c:c + k].shape) > (0.9 if step % 2 else holes)
        want = _fresh_fringe(observed, closing)
        # within 2 float32 ulps: OpenCV's rounding depends on the image size (rtol 2e-7 failed near 2^-7)
        np.testing.assert_array_max_ulp(fringe(observed, closing, window), want[window.slices], maxulp=2)
        np.testing.assert_array_max_ulp(fringe(observed, closing), want, maxulp=2)


def test_lazy_path_history_equals_adding_n_every_tick() -> None:
    """The stored 'tick last zeroed' gives the float32 values of adding n to every cell every tick."""
    g = GridGeometry(0.0, 0.0, 1.0, 30, 20)
    x, y = g.cell_centers()
    rng = np.random.default_rng(3)
    for n in (0.0, 0.013, 0.3, 1.0):
        lazy, plain = PathHistory(4.0, n), np.ones(g.shape, np.float32)
        for _ in range(150):
            d = np.hypot(x - rng.uniform(0, 30), y - rng.uniform(0, 20)).astype(np.float32)
            plain = np.minimum(plain + np.float32(n), np.float32(1.0))
            plain[d < 4.0] = 0.0
            np.testing.assert_array_equal(lazy.tick(g, d), plain)
        window = GridWindow(3, 11, 5, 25)
        np.testing.assert_array_equal(lazy.on(g, window), plain[window.slices])
