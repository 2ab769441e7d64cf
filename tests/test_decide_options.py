"""Behavior options: retargeting with hysteresis (on by default, can be switched off), terrain-aware altitude."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.decide import Behavior, DecisionMaker, Retarget, Terrain, terrain_altitude
from layerpilot.grid import GridGeometry
from layerpilot.layers import FeatureLayers

G = GridGeometry(-100.0, -100.0, 1.0, 200, 200)


def _blobs(*centres: tuple[float, float, float]) -> FeatureLayers:
    x, y = G.cell_centers()
    f = np.zeros(G.shape, np.float32)
    for cx, cy, height in centres:
        f = np.maximum(f, height * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / 30.0)).astype(np.float32)
    return FeatureLayers(G, {"fringe": f}, np.ones(G.shape, bool), np.zeros(G.shape, np.float32),
                    np.zeros((*G.shape, 3), np.uint8))


def _behavior(enabled: bool, **retarget: float) -> Behavior:
    return Behavior(weights={"fringe": 1.0}, r_e=10.0, r_i=100.0, noise=0.0,
                    retarget=Retarget(enabled=enabled, **retarget))


def test_retarget_switches_when_another_cell_is_clearly_better() -> None:
    dm = DecisionMaker(_behavior(True, margin=0.25, min_interval=5.0))
    first = dm.decide(_blobs((40.0, 0.0, 0.5)), (0.0, 0.0), 0.0)
    assert first.waypoint[:2] == pytest.approx((40.5, 0.5), abs=1.0)
    # a much better spot appears north while flying east
    better = _blobs((40.0, 0.0, 0.5), (10.0, 40.0, 1.0))
    assert dm.reconsider(better, (10.0, 0.0), 2.0) is None  # too soon after the last choice
    switched = dm.reconsider(better, (10.0, 0.0), 6.0)
    assert switched is not None and switched.retargeted and switched.waypoint[1] > 30
    assert dm.target is switched


def test_retarget_hysteresis_keeps_the_target_against_small_gains() -> None:
    dm = DecisionMaker(_behavior(True, margin=0.25, min_interval=0.0))
    first = dm.decide(_blobs((40.0, 0.0, 0.8)), (0.0, 0.0), 0.0)
    # a rival just 10% better: not enough to switch; the target's P stays as chosen while approaching
    rival = _blobs((40.0, 0.0, 0.8), (-40.0, 0.0, 0.88))
    for t, x in ((1.0, 5.0), (2.0, 15.0), (3.0, 25.0), (4.0, 35.0)):
        assert dm.reconsider(rival, (x, 0.0), t) is None
    assert dm.target is first
    # only when the target's own value collapses (seen, score gone) does the rival win
    gone = _blobs((-40.0, 0.0, 0.88))
    assert dm.reconsider(gone, (35.0, 0.0), 5.0).waypoint[0] < -30


def test_retarget_switched_off_never_switches() -> None:
    dm = DecisionMaker(_behavior(False))
    dm.decide(_blobs((40.0, 0.0, 0.5)), (0.0, 0.0), 0.0)
    assert dm.reconsider(_blobs((10.0, 40.0, 1.0)), (10.0, 0.0), 60.0) is None


def test_terrain_altitude_by_hand() -> None:
    g = GridGeometry(0.0, 0.0, 1.0, 20, 10)
    elev = np.full(g.shape, np.nan, np.float32)
    elev[5, :] = 3.0  # a strip along the path
    elev[5, 12] = 17.0  # a tree under the path
    elev[0, 12] = 40.0  # a taller tree 5 m off the path
    t = Terrain(enabled=True, clearance=10.0, corridor=2.0, min_altitude=15.0, max_altitude=60.0)
    assert terrain_altitude(elev, g, (0.5, 5.5), (19.5, 5.5), t, 50.0) == 27.0
    assert terrain_altitude(elev, g, (0.5, 5.5), (8.5, 5.5), t, 50.0) == 15.0  # 3 + 10 -> min limit
    wide = Terrain(enabled=True, clearance=10.0, corridor=5.0, min_altitude=15.0, max_altitude=45.0)
    assert terrain_altitude(elev, g, (0.5, 5.5), (19.5, 5.5), wide, 50.0) == 45.0  # 40 + 10 -> max limit
    unknown = np.full(g.shape, np.nan, np.float32)
    assert terrain_altitude(unknown, g, (0.5, 5.5), (19.5, 5.5), t, 50.0) == 50.0


def test_terrain_aware_waypoints() -> None:
    layers = _blobs((40.0, 0.0, 1.0))
    elevation = np.where(np.abs(G.cell_centers()[1]) < 3, 12.0, 0.0).astype(np.float32)
    layers = FeatureLayers(G, layers.layers, layers.observed, elevation, layers.rgb)
    flat = DecisionMaker(Behavior(weights={"fringe": 1.0}, altitude=50.0)).decide(layers, (0.0, 0.0, 50.0), 0.0)
    assert flat.waypoint[2] == 50.0
    aware = Behavior(weights={"fringe": 1.0}, altitude=50.0, terrain=Terrain(enabled=True, clearance=25.0))
    d = DecisionMaker(aware).decide(layers, (0.0, 0.0, 50.0), 0.0)
    assert d.waypoint[2] == 37.0 and d.runner_up is not None
