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
