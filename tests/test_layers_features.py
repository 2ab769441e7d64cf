"""Each built-in layer on small hand-computed grids."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.grid import GridGeometry
from layerpilot.layers import LayerContext, LayerOptions, compute_layers
from layerpilot.layers import features
from layerpilot.map.columns import ColumnLayers


def test_fringe_on_a_known_mask() -> None:
    observed = np.zeros((7, 7), bool)
    observed[:, :6] = True  # column 6 unobserved: the frontier is column 5
    f = features.fringe(observed, closing=0)
    assert f.dtype == np.float32
    np.testing.assert_allclose(f[3], [1 / 6, 1 / 5, 1 / 4, 1 / 3, 1 / 2, 1, 0], rtol=1e-6)
    # a diagonal-only unobserved neighbour still makes a frontier cell
    observed = np.ones((5, 5), bool)
    observed[0, 0] = False
    f = features.fringe(observed, closing=0)
    assert f[1, 1] == 1.0 and f[0, 1] == 1.0 and f[0, 0] == 0.0
    assert f[2, 2] == pytest.approx(1 / np.hypot(2, 2), rel=1e-6)
    assert (f[~observed] == 0).all() and f[observed].max() == 1.0


def test_fringe_closing_fills_small_holes_only() -> None:
    observed = np.zeros((20, 20), bool)
    observed[:, :15] = True
    observed[8, 5] = False  # a single-cell gap between trees
    open_ = features.fringe(observed, closing=0)
    assert open_[8, 4] == 1.0  # without closing the gap's neighbours look like frontier
    closed = features.fringe(observed, closing=3)
    assert closed[8, 4] < 1.0 and closed[8, 5] == pytest.approx(1 / 10, rel=1e-6)
    np.testing.assert_array_equal(closed[:, 14], 1.0)  # the true frontier is kept
    assert (closed[:, 15:] == 0).all()


def test_fringe_without_unobserved_or_observed_cells_is_zero() -> None:
    assert not features.fringe(np.ones((4, 4), bool)).any()
    assert not features.fringe(np.zeros((4, 4), bool)).any()
    with pytest.raises(ValueError, match="observed"):
        features.fringe(np.ones((4, 4), np.uint8))


def test_time_since_seen_scaling() -> None:
    observed = np.array([[True, True, True, False]])
    last_seen = np.array([[10.0, 40.0, 25.0, np.nan]])
    t = features.time_since_seen(observed, last_seen, now=50.0)
    # ages 40, 10, 25 -> (age - 10) / 30
    np.testing.assert_allclose(t, [[1.0, 0.0, 0.5, 0.0]])
    assert t.dtype == np.float32
    same = features.time_since_seen(observed, np.array([[5.0, 5.0, 5.0, np.nan]]), now=9.0)
    assert not same.any()
    with pytest.raises(ValueError, match="last_seen"):
        features.time_since_seen(observed, np.zeros((2, 4)), 1.0)


def test_min_distance_divides_by_100_and_drops_far_columns() -> None:
    observed = np.array([[True, True, True, False]])
    dist = np.array([[5.0, 100.0, 250.0, np.inf]], np.float32)
    np.testing.assert_allclose(features.min_distance(observed, dist), [[0.05, 1.0, 0.0, 0.0]])
    np.testing.assert_allclose(features.min_distance(observed, dist, max_distance=250.0), [[0.02, 0.4, 1.0, 0.0]])


def test_elevation_and_color() -> None:
    observed = np.array([[True, True, False]])
    top = np.array([[2.0, 6.0, np.nan]], np.float32)
    np.testing.assert_allclose(features.elevation(observed, top), [[0.0, 1.0, 0.0]])
    rgb = np.array([[[255, 0, 51], [0, 255, 0], [9, 9, 9]]], np.uint8)
    c = features.color(observed, rgb)
    np.testing.assert_allclose(c[0, 0], [1.0, 0.0, 0.2])
    assert (c[0, 2] == 0).all() and c.dtype == np.float32


def test_compute_layers_builds_a_checked_layer_set() -> None:
    g = GridGeometry(-2.0, -1.0, 1.0, 4, 3)
    cols = ColumnLayers.empty(g)
    cols.observed[1, :3] = True
    cols.elevation[1, :3] = [1.0, 2.0, 3.0]
    cols.last_seen[1, :3] = [0.0, 5.0, 10.0]
    cols.min_distance[1, :3] = [10.0, 20.0, 300.0]
    ls = compute_layers(cols, LayerContext(now=10.0, options=LayerOptions(fringe_closing=0)))
    assert set(ls.names) >= {"fringe", "time", "distance", "elevation"}
    np.testing.assert_allclose(ls["time"][1], [1.0, 0.5, 0.0, 0.0])
    np.testing.assert_allclose(ls["distance"][1], [0.1, 0.2, 0.0, 0.0])
    np.testing.assert_allclose(ls["fringe"][1], [1.0, 1.0, 1.0, 0.0])
    assert np.isnan(ls.elevation_m[0, 0]) and ls.elevation_m[1, 2] == 3.0
    assert ls.geometry == g and ls.now == 10.0
    with pytest.raises(ValueError, match="names: no layer named 'nope'"):
        compute_layers(cols, LayerContext(now=0.0), ["nope"])
    with pytest.raises(KeyError, match="no layer named 'x'"):
        ls["x"]
