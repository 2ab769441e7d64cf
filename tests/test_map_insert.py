"""Insertion: OctoMap's discretized ray model, attributes, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from layerpilot.bench._octomap import OcTree
from layerpilot.bench.map import all_voxels, compare_voxels
from layerpilot.eval.fixtures import survey_clouds
from layerpilot.map import SensorModel, VoxelMap


def logodds(p: float) -> float:
    return float(np.log(p / (1 - p)))


def prob(l: float) -> float:
    return float(1 / (1 + np.exp(-l)))


def test_single_ray_marks_free_space_and_occupied_endpoint() -> None:
    m = VoxelMap(1.0)
    r = m.insert(np.array([[10.5, 0.5, 0.5]], np.float32), np.array([0.5, 0.5, 0.5]), stamp=3.0)
    assert (r.points_used, r.points_dropped, r.voxels_occupied) == (1, 0, 1)
    assert r.voxels_updated == 11  # origin voxel + 9 between + endpoint
    occ = m.occupancy(np.array([[x + 0.5, 0.5, 0.5] for x in range(12)]))
    np.testing.assert_allclose(occ[:10], 0.4, atol=1e-6)  # one miss: prob_miss
    assert occ[10] == pytest.approx(0.7, abs=1e-6)  # one hit: prob_hit
    assert np.isnan(occ[11])  # beyond the endpoint: unknown


def test_repeated_hits_follow_log_odds_and_clamp() -> None:
    m = VoxelMap(1.0)
    pts = np.array([[5.5, 0.5, 0.5]], np.float32)
    expected = 0.0
    for _ in range(12):
        m.insert(pts, np.array([0.5, 0.5, 0.5]))
        expected = min(expected + logodds(0.7), logodds(0.971))
        assert m.occupancy(pts.astype(float))[0] == pytest.approx(prob(expected), abs=1e-5)
    assert m.occupancy(pts.astype(float))[0] == pytest.approx(0.971, abs=1e-4)


def test_custom_sensor_model_is_used() -> None:
    m = VoxelMap(0.5, model=SensorModel(prob_hit=0.9, prob_miss=0.2, occupied_threshold=0.8))
    m.insert(np.array([[3.2, 0.1, 0.1]], np.float32), np.zeros(3))
    occ = m.occupancy(np.array([[3.2, 0.1, 0.1], [1.1, 0.1, 0.1]]))
    assert occ == pytest.approx([0.9, 0.2], abs=1e-5)


def test_nan_and_inf_points_are_dropped_and_counted() -> None:
    m = VoxelMap(1.0)
    pts = np.array([[np.nan, 0, 0], [5, np.inf, 0], [5.5, 0.5, 0.5], [-np.inf, 1, 1]], np.float32)
    r = m.insert(pts, np.array([0.5, 0.5, 0.5]))
    assert (r.points_used, r.points_dropped, r.voxels_occupied) == (1, 3, 1)


def test_all_nan_frame_changes_nothing() -> None:
    m = VoxelMap(1.0)
    r = m.insert(np.full((1000, 3), np.nan, np.float32), np.zeros(3))
    assert (r.points_used, r.points_dropped, r.voxels_updated) == (0, 1000, 0)
    assert m.stats()["leaves"] == 0


def test_endpoint_beyond_max_range_clears_up_to_max_range_only() -> None:
    m = VoxelMap(1.0)
    r = m.insert(np.array([[50.5, 0.5, 0.5]], np.float32), np.array([0.5, 0.5, 0.5]), max_range=20.0)
    assert r.voxels_occupied == 0
    occ = m.occupancy(np.array([[x + 0.5, 0.5, 0.5] for x in (0, 10, 19, 21, 50)]))
    np.testing.assert_allclose(occ[:3], 0.4, atol=1e-6)
    assert np.isnan(occ[3]) and np.isnan(occ[4])


def test_attributes_last_seen_min_distance_and_latest_color() -> None:
    m = VoxelMap(1.0)
    target = np.array([[20.5, 0.5, 0.5], [20.7, 0.2, 0.9]], np.float32)  # both in one voxel
    m.insert(target, np.array([0.5, 0.5, 0.5]), np.array([[100, 0, 0], [200, 50, 0]], np.uint8), stamp=1.0)
    m.insert(target[:1], np.array([10.5, 0.5, 0.5]), np.array([[0, 0, 255]], np.uint8), stamp=7.5)
    m.insert(target[:1], np.array([-9.5, 0.5, 0.5]), np.array([[0, 255, 0]], np.uint8), stamp=9.0)
    v = m.voxels(np.array([20, 0, 0]), np.array([21, 1, 1]))
    assert len(v) == 1
    assert v.last_seen[0] == pytest.approx(9.0)
    assert v.min_distance[0] == pytest.approx(10.0, abs=1e-5)  # from the second origin
    assert v.color[0].tolist() == [0, 255, 0]  # latest observation
    m2 = VoxelMap(1.0)
    m2.insert(target, np.array([0.5, 0.5, 0.5]), np.array([[100, 0, 0], [200, 50, 0]], np.uint8))
    assert m2.voxels(np.array([20, 0, 0]), np.array([21, 1, 1])).color[0].tolist() == [150, 25, 0]  # frame mean


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"points": np.zeros((4, 2), np.float32)}, "points: expected shape"),
        ({"points": np.zeros((4, 3), str)}, "points: expected dtype"),
        ({"origin": np.zeros(4)}, "origin: expected shape"),
        ({"origin": np.array([0, np.nan, 0])}, "origin: must be finite"),
        ({"colors": np.zeros((3, 3), np.uint8)}, "colors: expected shape"),
        ({"colors": np.zeros((4, 3), np.float32)}, "colors: expected dtype uint8"),
        ({"max_range": -1.0}, "max_range"),
        ({"stamp": float("nan")}, "stamp"),
    ],
)
def test_bad_input_names_the_argument(kwargs: dict, message: str) -> None:
    args = {"points": np.zeros((4, 3), np.float32), "origin": np.ones(3)} | kwargs
    with pytest.raises(ValueError, match=message):
        VoxelMap(1.0).insert(**args)


def test_float64_points_are_accepted() -> None:
    m = VoxelMap(1.0)
    assert m.insert(np.array([[4.5, 0.5, 0.5]]), np.array([0.5, 0.5, 0.5])).voxels_occupied == 1


@pytest.fixture(scope="module")
def frames():
    return survey_clouds(3, seed=5, width=160, height=120)


def test_agrees_with_octomap_discretized_insertion(frames) -> None:
    """Every voxel has OctoMap's log-odds (as an occupancy probability, bit for bit)."""
    ours, ref = VoxelMap(1.0), OcTree(1.0)
    for f in frames:
        ours.insert(f.points, f.origin, f.colors, f.stamp)
        ref.insert(f.points[np.isfinite(f.points).all(axis=1)], f.origin, 100.0, True)
    same = compare_voxels(all_voxels(ours), ref.voxels(), 1.0)
    assert same["identical"] == same["voxels"] > 20000
    assert (all_voxels(ours)[1] >= 0.5).sum() > 500


def test_memory_stats(frames) -> None:
    m = VoxelMap(1.0)
    for f in frames:
        m.insert(f.points, f.origin, f.colors, f.stamp)
    s = m.stats()
    assert s["node_bytes"] == 8
    assert s["leaves"] > 10000 and s["nodes"] > s["leaves"]
    # One 64-byte group of children per inner node, one 12-byte record per voxel ever hit.
    assert s["tree_bytes"] >= (s["nodes"] - s["leaves"]) * 64 + s["attribute_records"] * 12
    hit = m.voxels(np.full(3, -500.0), np.full(3, 500.0), min_occupancy=0.0).last_seen
    assert 1000 < s["attribute_records"] <= np.isfinite(hit).sum()  # a pruned leaf's record covers 8+ voxels
    assert s["total_bytes"] == s["tree_bytes"] + s["column_index_bytes"] > 0
    assert s["bytes_per_leaf"] == s["total_bytes"] / s["leaves"]
    assert s["insert_scratch_bytes"] > 0
