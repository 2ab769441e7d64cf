"""Layers and a decision from a real VoxelMap built by inserting clouds."""

from __future__ import annotations

import numpy as np

from layerpilot.decide import DecisionMaker, area_geometry, load_behavior
from layerpilot.layers import LayerContext, compute_layers
from layerpilot.map import VoxelMap


def _ground(x0: float, x1: float, y0: float, y1: float, z: float) -> np.ndarray:
    xs, ys = np.meshgrid(np.arange(x0, x1, 0.5) + 0.25, np.arange(y0, y1, 0.5) + 0.25)
    return np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, z)]).astype(np.float32)


def test_layers_and_decision_from_inserted_clouds() -> None:
    m = VoxelMap(1.0)
    # t = 0: the west half of a 40 x 40 m patch, seen from 20 m above its centre
    west = _ground(-20, 0, -20, 20, 0.2)
    m.insert(west, np.array([-10.0, 0.0, 20.0]), np.full((len(west), 3), 200, np.uint8), stamp=0.0)
    # t = 30: the east half, seen from 60 m up (farther)
    east = _ground(0, 20, -20, 20, 0.2)
    m.insert(east, np.array([10.0, 0.0, 60.0]), np.full((len(east), 3), 50, np.uint8), stamp=30.0)
    # a 5 m tall 'tree' column in the east half
    tree = np.array([[10.5, 0.5, 5.5]], np.float32)
    m.insert(tree, np.array([10.5, 0.5, 60.0]), stamp=30.0)

    behavior = load_behavior("balanced")
    geometry = area_geometry(behavior.area, (0.0, 0.0))
    columns = m.column_layers_for(geometry)
    layers = compute_layers(columns, LayerContext(now=40.0), ["fringe", "time", "distance", "elevation"])
    cell = lambda x, y: geometry.cell_of(x, y)  # noqa: E731

    assert layers.observed.sum() == 40 * 40
    # time: the west half is oldest (age 40 vs 10) -> 1, the east half freshest -> 0
    assert layers["time"][cell(-10, 5)] == 1.0 and layers["time"][cell(10, 5)] == 0.0
    # distance: seen from ~20 m (west) vs ~60 m (east), divided by 100 m
    assert 0.19 < layers["distance"][cell(-10, 0)] < 0.23
    assert 0.59 < layers["distance"][cell(10, 5)] < 0.63
    # fringe: the patch's edge is 1, its middle is deep (distance >= 19 cells to unobserved)
    assert layers["fringe"][cell(-19.5, 0)] == 1.0 and layers["fringe"][cell(0, 0)] <= 1 / 19
    assert layers["fringe"][cell(50, 50)] == 0.0
    # elevation: the tree is the highest column
    assert layers["elevation"][cell(10.5, 0.5)] == 1.0 and layers.elevation_m[cell(10.5, 0.5)] >= 5.0
    np.testing.assert_allclose(layers.color[cell(-10, 0)], [200 / 255] * 3)

    decision = DecisionMaker(behavior).decide(layers, (0.0, 0.0, 50.0), 40.0)
    x, y, z = decision.waypoint
    assert decision.fallback is None and decision.score > 0 and z == 50.0
    assert 10.0 <= np.hypot(x, y) <= 100.0
    # balanced: fringe + old + far-seen cells win: the patch's edge
    r, c = decision.cell
    assert layers["fringe"][r, c] == 1.0
    assert decision.coverage == np.count_nonzero(layers.observed) / np.count_nonzero(
        (np.hypot(*geometry.cell_centers()) <= 100.0))
