"""Paper metrics on hand-made grids and voxel sets with known answers, and on a real map."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.eval.metrics import (
    area_metrics,
    disk_mask,
    map_voxel_metrics,
    nearest_distances,
    voxel_metrics,
)
from layerpilot.grid import GridGeometry
from layerpilot.map.columns import ColumnLayers


def _layers() -> ColumnLayers:
    g = GridGeometry(0.0, 0.0, 1.0, 4, 3)
    layers = ColumnLayers.empty(g)
    for (r, c), seen, dist in [((0, 0), 10.0, 5.0), ((1, 1), 40.0, 250.0), ((2, 3), 0.0, 1.0)]:
        layers.observed[r, c] = True
        layers.last_seen[r, c] = seen
        layers.min_distance[r, c] = dist
    return layers


def test_area_metrics_known_answer() -> None:
    layers = _layers()
    aoi = np.zeros((3, 4), bool)
    aoi[:2, :] = True  # 8 cells; (0,0) and (1,1) mapped inside, (2,3) outside
    m = area_metrics(layers, aoi, now=50.0)
    assert m.percent_mapped == pytest.approx(25.0)
    assert m.avg_time_since_observed == pytest.approx((40.0 + 10.0) / 2)
    assert m.avg_min_distance == pytest.approx((5.0 + 100.0) / 2)  # 250 m capped at 100


def test_area_metrics_nothing_mapped_and_bad_input() -> None:
    layers = ColumnLayers.empty(GridGeometry(0.0, 0.0, 1.0, 4, 3))
    m = area_metrics(layers, np.ones((3, 4), bool), now=1.0)
    assert m.percent_mapped == 0.0 and np.isnan(m.avg_time_since_observed) and np.isnan(m.avg_min_distance)
    with pytest.raises(ValueError, match="aoi"):
        area_metrics(layers, np.ones((4, 3), bool), now=1.0)
    with pytest.raises(ValueError, match="aoi"):
        area_metrics(layers, np.zeros((3, 4), bool), now=1.0)


def test_disk_mask_counts_cell_centres() -> None:
    g = GridGeometry.centered(0.0, 0.0, 1.0, 10, 10)
    mask = disk_mask(g, (0.0, 0.0), 1.0)
    # centres at (+-0.5, +-0.5) only are within 1 m of the origin
    assert mask.sum() == 4
    assert disk_mask(g, (0.0, 0.0), 100.0).all()


def test_nearest_distances_matches_brute_force() -> None:
    rng = np.random.default_rng(3)
    ref = rng.uniform(-30, 30, (2000, 3))
    pts = np.concatenate([rng.uniform(-40, 40, (1500, 3)), [[500.0, -300.0, 20.0]]])  # one far outlier
    brute = np.sqrt(((pts[:, None, :] - ref[None, :, :]) ** 2).sum(-1)).min(1)
    np.testing.assert_allclose(nearest_distances(pts, ref), brute, rtol=0, atol=1e-9)
    exact = nearest_distances(np.array([[3.0, 4.0, 0.0]]), np.zeros((1, 3)), max_distance=5.0)
    assert exact[0] == 5.0  # a neighbour at exactly max_distance counts
    assert np.isinf(nearest_distances(pts[:3], np.zeros((0, 3)))).all()
    with pytest.raises(ValueError, match="reference"):
        nearest_distances(pts, ref[:, :2])


def test_voxel_metrics_known_answer() -> None:
    gt = np.array([[0, 0, 0], [10, 0, 0], [20, 0, 0], [30, 0, 0]], float)
    # est: one exact hit, one 3 m off, one 5 m off (outside d_v = 4), one 100 m away
    est = np.array([[0, 0, 0], [10, 3, 0], [20, 0, 5], [130, 0, 0]], float)
    m = voxel_metrics(est, gt, d_v=4.0)
    assert m.paper_recall == pytest.approx(2 / 4)
    assert m.paper_mse == pytest.approx((0 + 3 + 5 + 100) / 4)
    assert m.precision == pytest.approx(2 / 4)
    assert m.recall == pytest.approx(2 / 4)  # gt at 30 is 100 m from any est voxel
    assert m.f_score == pytest.approx(0.5)
    assert (m.n_est, m.n_gt) == (4, 4)


def test_paper_recall_counts_estimated_voxels_so_it_can_exceed_one() -> None:
    gt = np.zeros((1, 3))
    est = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0]], float)  # three est voxels near one gt voxel
    m = voxel_metrics(est, gt)
    assert m.paper_recall == pytest.approx(3.0)
    assert m.recall == pytest.approx(1.0) and m.precision == pytest.approx(1.0)
    assert m.paper_mse == pytest.approx(1.0)
    empty = voxel_metrics(np.zeros((0, 3)), gt)
    assert empty.recall == 0.0 and np.isnan(empty.precision) and np.isnan(empty.paper_mse)


def test_map_voxel_metrics_on_real_maps() -> None:
    from layerpilot.map import VoxelMap

    # A 20 m x 20 m wall at x = 20; ground truth sees all of it, the estimate sees the
    # southern half shifted 2 m in x (inside d_v) and a stray blob far away.
    ys, zs = np.meshgrid(np.arange(-10, 10, 0.25), np.arange(0, 20, 0.25))
    wall = np.stack([np.full(ys.size, 20.2), ys.ravel(), zs.ravel()], 1).astype(np.float32)
    gt_map, est_map = VoxelMap(1.0), VoxelMap(1.0)
    origin = np.array([0.0, 0.0, 10.0])
    south = wall[wall[:, 1] < 0] + np.array([2.0, 0.0, 0.0], np.float32)
    blob = np.array([[0.5, 40.5, 10.5]] * 4, np.float32)
    for _ in range(2):  # two hits: occupancy 0.845 > 0.7
        gt_map.insert(wall, origin)
        est_map.insert(np.concatenate([south, blob]), origin)
    lo, hi = np.array([-50.0, -50, -5]), np.array([50.0, 50, 30])
    m = map_voxel_metrics(est_map, gt_map, lo, hi)
    assert (m.n_gt, m.n_est) == (400, 201)  # 20x20 wall voxels; 10x20 shifted + blob
    # gt rows y = 0.5, 1.5, 2.5 are sqrt(2^2 + dy^2) <= 4 m from the estimate's row y = -0.5
    assert m.recall == pytest.approx((200 + 3 * 20) / 400)
    assert m.precision == pytest.approx(200 / 201)
    assert m.paper_recall == pytest.approx(200 / 400)
    blob_d = np.linalg.norm(np.array([0.5, 40.5, 10.5]) - np.array([20.5, 9.5, 10.5]))
    assert m.paper_mse == pytest.approx((200 * 2.0 + blob_d) / 201)
    # one hit is exactly 0.7: not "above 0.7", so a single-hit map has no V_est voxels
    once = VoxelMap(1.0)
    once.insert(wall, origin)
    assert map_voxel_metrics(once, gt_map, lo, hi).n_est == 0


def test_nearest_distances_max_distance_stops_early_but_stays_exact_within() -> None:
    rng = np.random.default_rng(5)
    ref = rng.uniform(0, 10, (300, 3))
    pts = np.concatenate([rng.uniform(0, 10, (200, 3)), rng.uniform(100, 120, (50, 3))])
    full = nearest_distances(pts, ref)
    capped = nearest_distances(pts, ref, max_distance=4.0)
    near = full <= 4.0
    np.testing.assert_array_equal(capped[near], full[near])
    assert np.isinf(capped[~near]).all() and (~near).sum() == 50
