"""World generation: determinism by seed, content, ground truth, config validation."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.config import ConfigError, from_dict
from layerpilot.grid import GridGeometry
from layerpilot.sim.world import BROADLEAF, CONIFER, GROUND, World, WorldConfig

SMALL = WorldConfig(seed=3, size=120.0, trees_per_hectare=250.0, clearings=2)


def test_default_world_is_a_forest_of_thousands_of_trees_on_hills():
    w = World()
    s = w.stats()
    assert s["size_m"] >= 400
    assert 2500 <= s["trees"] <= 3200
    assert 0.4 < s["conifers"] / s["trees"] < 0.6
    assert s["terrain_max_m"] - s["terrain_min_m"] > 15.0  # hills of tens of metres
    assert np.all(np.abs(w.vertices[:, :2]) <= 200.0 + 5.0)
    # launch clearing: no trunk within its radius
    assert np.min(np.hypot(w.trees.x, w.trees.y)) > 20.0


def test_same_seed_same_world_other_seed_other_world():
    a, b, c = World(SMALL), World(SMALL), World(WorldConfig(seed=4, size=120.0, trees_per_hectare=250.0, clearings=2))
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.triangles, b.triangles)
    assert np.array_equal(a.materials, b.materials)
    assert not np.array_equal(a.heightfield, c.heightfield)
    assert not np.array_equal(a.trees.x[:10], c.trees.x[:10])


def test_terrain_height_matches_mesh_vertices_and_is_planar_per_triangle():
    w = World(SMALL)
    ground = w.materials == GROUND
    v = w.vertices[ground]
    assert np.allclose(w.terrain_height(v[:, 0], v[:, 1]), v[:, 2], atol=1e-4)
    # centroid of every terrain triangle lies on the interpolated surface
    tri = w.triangles[w.materials[w.triangles[:, 0]] == GROUND]
    cen = w.vertices[tri].astype(np.float64).mean(axis=1)
    assert np.allclose(w.terrain_height(cen[:, 0], cen[:, 1]), cen[:, 2], atol=1e-4)


def test_surface_height_is_tree_top_over_trees_and_terrain_elsewhere():
    w = World(SMALL)
    geo = GridGeometry(-60.0, -60.0, 0.5, 240, 240)
    top = w.surface_height(geo)
    cx, cy = geo.cell_centers()
    terrain = w.terrain_height(cx, cy)
    assert top.shape == (240, 240) and top.dtype == np.float32
    assert np.all(top >= terrain - 1e-4)
    # the launch clearing is bare ground
    bare = np.hypot(cx, cy) < 15.0
    assert np.allclose(top[bare], terrain[bare], atol=1e-4)
    # over each conifer axis the surface is the apex: ground + height (cone apex)
    for k in np.flatnonzero(w.trees.kind == CONIFER)[:20]:
        r, c = geo.cell_of(w.trees.x[k], w.trees.y[k])
        if not geo.contains(r, c):
            continue
        x, y = geo.cell_center(r, c)
        d = np.hypot(x - w.trees.x[k], y - w.trees.y[k])
        apex = w.trees.ground[k] + w.trees.height[k]
        slope = 0.75 * w.trees.height[k] / (w.trees.crown_radius[k] * np.cos(np.pi / 7))
        assert top[r, c] >= apex - slope * d - 0.05  # a taller neighbour may overtop it
    # raised cells lie under some crown, and no surface is above the tallest tree
    raised = top > terrain + 0.01
    t = w.trees
    near = np.zeros_like(raised)
    for k in range(len(t)):
        near |= np.hypot(cx - t.x[k], cy - t.y[k]) <= t.crown_radius[k] + 0.01
    assert raised.sum() > 0.2 * raised.size
    assert np.all(near[raised])
    assert top.max() <= np.max(t.ground + t.height) + 0.01
    assert np.sum(t.kind == BROADLEAF) > 0


def test_config_is_validated_naming_the_key():
    with pytest.raises(ConfigError, match="trees_per_hectare"):
        from_dict(WorldConfig, {"trees_per_hectare": -1.0}, "world")
    with pytest.raises(ConfigError, match="world.sise"):
        from_dict(WorldConfig, {"sise": 100.0}, "world")
    assert from_dict(WorldConfig, {"seed": 7, "size": 600}, "world").size == 600.0


def test_harder_world_options_give_ridges_fields_and_tall_stands_and_leave_the_default_alone() -> None:
    plain = World(WorldConfig(seed=4, size=300.0))
    hard = World(WorldConfig(seed=4, size=640.0, ridge_height=60.0, fields=6, tall_stand_height=35.0))
    x = np.linspace(-300, 300, 241)
    gx, gy = np.meshgrid(x, x)
    ridge = hard._ridges(np.random.default_rng([4, 1]), gx, gy)
    assert ridge.max() - ridge.min() > 50.0 and abs(float(hard._ridges(np.random.default_rng([4, 1]),
                                                                         np.zeros(1), np.zeros(1))[0])) < 1e-9
    h = hard.terrain_height(gx, gy)
    assert h.max() - h.min() > 60.0
    # no tree in a field, none at the launch point; tall stands exist and keep to their cap
    assert len(hard.fields) == 6 and not hard.in_field(hard.trees.x, hard.trees.y).any()
    assert not hard.in_field(np.zeros(1), np.zeros(1))[0]
    tall = hard.trees.height > hard.config.tree_height_max
    assert 0.05 < tall.mean() < 0.6 and hard.trees.height.max() <= 35.0
    # the options draw from their own generator: the hills, clearings and tree places of the seed stay
    flat = World(WorldConfig(seed=4, size=640.0, fields=6, tall_stand_height=35.0))
    base = World(WorldConfig(seed=4, size=640.0))
    assert np.array_equal(flat.heightfield, base.heightfield) and np.array_equal(flat.clearings, base.clearings)
    assert np.allclose(hard.heightfield - flat.heightfield, hard._ridges(np.random.default_rng([4, 1]),
                                                                        *np.meshgrid(*2 * [np.linspace(-320, 320, 321)])))
    assert len(plain.fields) == 0
    with pytest.raises(ValueError, match="tall_stand_height"):
        WorldConfig(tall_stand_height=10.0)
