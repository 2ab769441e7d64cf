"""The incremental column index against a brute-force walk over the octree's leaves."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.grid import GridGeometry
from layerpilot.map import VoxelMap


def brute_force_columns(m: VoxelMap, x0: float, y0: float, w: int, h: int):
    """Top occupied voxel per column from every occupied leaf (the slow way)."""
    res = m.resolution
    v = m.voxels(np.array([x0, y0, -1000.0]), np.array([x0 + w * res - 1e-3, y0 + h * res - 1e-3, 1000.0]))
    top = np.full((h, w), -np.inf)
    attrs = {}
    cols = np.floor((v.centers[:, 0] - x0) / res).astype(int)
    rows = np.floor((v.centers[:, 1] - y0) / res).astype(int)
    for i, (r, c) in enumerate(zip(rows, cols)):
        if v.centers[i, 2] > top[r, c]:
            top[r, c] = v.centers[i, 2]
            attrs[r, c] = (v.color[i], v.last_seen[i], v.min_distance[i])
    return top, attrs


def random_scene_inserts(m: VoxelMap, rng: np.random.Generator, frames: int) -> None:
    for k in range(frames):
        origin = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(15, 25)])
        n = 3000
        xy = rng.uniform(-30, 30, (n, 2))
        z = np.sin(xy[:, 0] / 5) * 3 + rng.choice([0.0, 6.0], n, p=[0.8, 0.2])
        pts = np.column_stack([xy, z]).astype(np.float32)
        m.insert(pts, origin, rng.integers(0, 255, (n, 3), dtype=np.uint8), stamp=float(k))


def assert_index_matches(m: VoxelMap, x0: float, y0: float, w: int, h: int) -> int:
    cl = m.column_layers(x0, y0, w, h)
    top, attrs = brute_force_columns(m, cl.geometry.origin_x, cl.geometry.origin_y, w, h)
    observed = np.isfinite(top)
    np.testing.assert_array_equal(cl.observed, observed)
    np.testing.assert_allclose(cl.elevation[observed], top[observed] + 0.5 * m.resolution, atol=1e-5)
    assert np.all(np.isnan(cl.elevation[~observed]))
    for (r, c), (color, seen, dist) in attrs.items():
        assert cl.color[r, c].tolist() == color.tolist()
        assert cl.last_seen[r, c] == pytest.approx(seen)
        assert cl.min_distance[r, c] == pytest.approx(dist)
    return int(observed.sum())


def test_column_index_matches_brute_force_after_random_inserts() -> None:
    m = VoxelMap(1.0)
    random_scene_inserts(m, np.random.default_rng(3), 8)
    assert assert_index_matches(m, -40, -40, 80, 80) > 2000


def test_column_whose_top_voxel_turns_free_falls_back_to_the_next_voxel() -> None:
    m = VoxelMap(1.0)
    origin = np.array([0.5, 0.5, 30.5])
    m.insert(np.array([[10.5, 0.5, 5.5], [10.5, 0.5, 1.5]], np.float32), origin,
             np.array([[255, 0, 0], [0, 0, 255]], np.uint8), stamp=1.0)
    m.insert(np.array([[10.5, 0.5, 1.5]], np.float32), origin, np.array([[0, 0, 255]], np.uint8), stamp=2.0)
    cl = m.column_layers(10, 0, 1, 1)
    assert cl.elevation[0, 0] == pytest.approx(6.0) and cl.color[0, 0].tolist() == [255, 0, 0]
    # Rays from the side pass through the top voxel (z 5.5) and end beyond it: it turns free.
    side = np.array([[30.5, 0.5, 5.5]], np.float32)
    for k in range(3):
        m.insert(side, np.array([0.5, 0.5, 5.5]), stamp=3.0 + k)
    assert m.occupancy(np.array([[10.5, 0.5, 5.5]]))[0] < 0.5
    cl = m.column_layers(10, 0, 1, 1)
    assert cl.observed[0, 0]
    assert cl.elevation[0, 0] == pytest.approx(2.0)
    assert cl.color[0, 0].tolist() == [0, 0, 255]
    assert cl.last_seen[0, 0] == pytest.approx(2.0)
    assert_index_matches(m, 0, -5, 40, 10)


def test_index_survives_save_and_load(tmp_path) -> None:
    m = VoxelMap(1.0)
    random_scene_inserts(m, np.random.default_rng(4), 3)
    m.save(tmp_path / "m.ot")
    loaded = VoxelMap.load(tmp_path / "m.ot")
    a, b = m.column_layers(-40, -40, 80, 80), loaded.column_layers(-40, -40, 80, 80)
    for name in ("observed", "elevation", "color", "last_seen", "min_distance"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_window_geometry_and_empty_regions() -> None:
    m = VoxelMap(0.5)
    m.insert(np.array([[3.3, 2.2, 1.0]], np.float32), np.array([0.2, 0.2, 10.0]))
    cl = m.column_layers(-0.2, 0.9, 16, 8)
    assert cl.geometry == GridGeometry(-0.5, 0.5, 0.5, 16, 8)
    row, col = cl.geometry.cell_of(3.3, 2.2)
    assert cl.observed.sum() == 1 and cl.observed[row, col]
    assert cl.elevation[row, col] == pytest.approx(1.5)
    far = m.column_layers(5000, 5000, 512, 512)
    assert far.observed.shape == (512, 512) and not far.observed.any()
    same = m.column_layers_for(cl.geometry)
    np.testing.assert_array_equal(same.observed, cl.observed)
    with pytest.raises(ValueError, match="width, height"):
        m.column_layers(0, 0, 0, 5)
