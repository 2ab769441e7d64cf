"""Scoring up to the common offset: real maps shifted by known translations, and pose errors."""

from __future__ import annotations

import bz2
from pathlib import Path

import numpy as np
import pytest

from layerpilot.eval.alignment import SCORE_NAMES, MapScorer, best_offset
from layerpilot.eval.metrics import MAP_METRICS
from layerpilot.eval.pose_errors import common_offset, pose_errors
from layerpilot.geometry import Pose, quat_from_euler
from layerpilot.grid import GridGeometry
from layerpilot.map import VoxelMap

BOX = (np.array([-30.0, -30.0, -10.0]), np.array([40.0, 30.0, 20.0]))
GEOMETRY = GridGeometry(-30.0, -30.0, 0.5, 140, 120)


@pytest.fixture(scope="module")
def scan(octomap_data: Path) -> np.ndarray:
    """OctoMap's real laser scan (88,206 points around a sensor at the origin)."""
    return np.loadtxt(bz2.open(octomap_data / "scan.dat.bz2", "rt"), dtype=np.float32)


def _map(points: np.ndarray, shift, stamp: float = 1.0) -> VoxelMap:
    m = VoxelMap(0.5)
    shift = np.asarray(shift, np.float32)
    for _ in range(2):  # two hits: above the 0.7 the 3D metrics count
        m.insert(points + shift, shift.astype(np.float64), stamp=stamp, max_range=1000.0)
    return m


def _scorer() -> MapScorer:
    aoi = np.zeros(GEOMETRY.shape, bool)
    aoi[30:90, 60:110] = True  # the part of the scan's surroundings the sensor saw
    return MapScorer(GEOMETRY, aoi, *BOX)


def test_identical_maps_score_the_same_both_ways_with_offset_exactly_zero(scan: np.ndarray) -> None:
    truth, est = _map(scan, (0, 0, 0)), _map(scan[::2], (0, 0, 0))  # the estimate saw every other point
    scores = _scorer()(est, truth, now=5.0)
    assert list(scores) == SCORE_NAMES
    assert [scores[k] for k in ("offset_x", "offset_y", "offset_z")] == [0.0, 0.0, 0.0]
    for k in MAP_METRICS:
        assert scores[k] == scores[f"{k}_absolute"] or np.isnan(scores[k]) and np.isnan(scores[f"{k}_absolute"]), k
    assert scores["percent_mapped"] > 20.0 and scores["f_score"] > 0.99


@pytest.mark.parametrize("shift", [(2.0, -3.0, 1.5), (1.4, -2.6, 0.7), (9.0, 6.5, -4.0)])
def test_a_shifted_real_map_is_put_back(scan: np.ndarray, shift) -> None:
    truth, est = _map(scan, (0, 0, 0)), _map(scan[1::2], shift)
    scorer = _scorer()
    scores = scorer(est, truth, now=5.0)
    assert np.all(np.abs(scorer.offset - shift) <= 0.5)  # whole voxels of 0.5 m: within one of the shift
    assert np.all(scorer.offset % 0.5 == 0)
    if np.all(np.array(shift) % 0.5 == 0):  # a shift of whole voxels is found exactly
        np.testing.assert_array_equal(scorer.offset, shift)
    assert [scores[k] for k in ("offset_x", "offset_y", "offset_z")] == list(scorer.offset)
    assert scores["f_score"] > 0.99 and scores["precision"] > 0.99
    assert scores["f_score_absolute"] <= scores["f_score"]
    assert scores["paper_mse"] < 0.2 and scores["paper_mse_absolute"] > 1.0  # mean distance to the truth
    if shift[0] > 5:  # beyond d_v = 4 m most voxels find no match without the alignment
        assert scores["f_score_absolute"] < 0.7 and scores["percent_mapped_absolute"] < scores["percent_mapped"]


def test_the_search_starts_where_the_last_one_ended(scan: np.ndarray) -> None:
    truth = _map(scan, (0, 0, 0))
    moved = _map(scan, (20.0, 0.0, 0.0))
    assert best_offset(moved.voxels(*BOX).centers, truth.voxels(*BOX).centers, 0.5, start=(19.0, 0.5, 0.0))[0] == 20.0
    with pytest.raises(ValueError, match="est"):
        best_offset(np.zeros((3, 2)), np.zeros((3, 3)), 0.5)
    assert not best_offset(np.zeros((0, 3)), truth.voxels(*BOX).centers, 0.5).any()


def _path(n: int) -> list[tuple[float, Pose]]:
    return [(float(t), Pose((5.0 * t, 2.0, 40.0), quat_from_euler(0.0, 0.0, 0.1 * t))) for t in range(n)]


def test_pose_errors_remove_the_offset_and_measure_the_rest() -> None:
    truth = _path(10)
    offset = np.array([1.5, -2.0, 3.0])
    # position errors 0.0, 0.1, ..., 0.9 m beside the offset; attitude off by 0..9 degrees of roll
    estimate = [(t + 0.08, Pose(p.position + offset + (0.0, 0.0, 0.1 * i),
                                quat_from_euler(np.radians(i), 0.0, 0.1 * t)))
                for i, (t, p) in enumerate(truth)]
    e = pose_errors(truth, estimate, offset)
    assert e.poses == 10
    assert e.position_median == pytest.approx(0.45) and e.position_p90 == pytest.approx(0.81)
    assert e.attitude_median_deg == pytest.approx(4.5) and e.attitude_p90_deg == pytest.approx(8.1)
    raw = pose_errors(truth, estimate).as_dict("raw")
    assert raw["raw_position_median"] == pytest.approx(np.linalg.norm(offset + (0, 0, 0.45)), abs=0.05)
    with pytest.raises(ValueError, match="no true pose"):
        pose_errors(truth, [(30.0, truth[0][1])])
    with pytest.raises(ValueError, match="offset"):
        pose_errors(truth, estimate, (1.0, 2.0))


def test_a_mission_scorer_follows_a_wandering_offset(scan: np.ndarray) -> None:
    """Sample after sample the search starts from the last offset (steps of 2 and 1 voxels)."""
    truth, scorer = _map(scan, (0, 0, 0)), _scorer()
    assert scorer(VoxelMap(0.5), truth, now=0.0)["offset_x"] == 0.0 and not scorer.searched  # nothing mapped yet
    for drift in [(0.0, 0.0, 0.0), (1.0, -0.5, 0.5), (2.5, -1.0, 1.0), (4.0, -2.0, 0.0), (1.0, 0.0, 0.0)]:
        scores = scorer(_map(scan[::3], drift), truth, now=5.0)
        assert [scores[k] for k in ("offset_x", "offset_y", "offset_z")] == list(drift)


def test_with_camera_poses_the_offset_is_theirs_and_a_biased_map_is_not_forgiven(scan: np.ndarray) -> None:
    """The scan's sensor flies a short line; its map is built 1.4, -2.6, 0.7 m off (a GNSS offset)."""
    truth_map = _map(scan, (0, 0, 0))
    gnss = np.array([1.4, -2.6, 0.7])
    truth = _path(10)
    placed = [(t, Pose(p.position + gnss + (0.05 * (-1) ** i, 0.0, 0.0), p.orientation))
              for i, (t, p) in enumerate(truth)]
    scorer = _scorer()
    scores = scorer(_map(scan[1::2], gnss), truth_map, 5.0, (truth, placed))
    assert [scores[k] for k in ("offset_x", "offset_y", "offset_z")] == [1.5, -2.5, 0.5]  # the median, in voxels
    assert scores["paper_mse"] < 0.3 < scores["paper_mse_absolute"]
    # a map 1.5 m off that its (perfect) poses do not explain is the map's own error: scored as it is
    scores = scorer(_map(scan[1::2], (0.0, 0.0, 1.5)), truth_map, 5.0, (truth, truth))
    assert [scores[k] for k in ("offset_x", "offset_y", "offset_z")] == [0.0, 0.0, 0.0]
    assert all(scores[k] == scores[f"{k}_absolute"] for k in ("f_score", "precision", "paper_mse"))
    assert scorer(_map(scan[1::2], gnss), truth_map, 5.0, ([], placed))["offset_x"] == 0.0  # nothing to pair yet
    np.testing.assert_allclose(common_offset(truth, placed), gnss + (0.0, 0.0, 0.0), atol=0.05 + 1e-12)
