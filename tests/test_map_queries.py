"""Occupancy of many points, ray casts, voxels in a box, and reading while inserting."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from layerpilot.eval.fixtures import survey_clouds
from layerpilot.map import VoxelMap


@pytest.fixture()
def wall() -> VoxelMap:
    """A wall of occupied voxels at x = 20 seen from the origin."""
    m = VoxelMap(1.0)
    yz = np.mgrid[-5:6, -5:6].reshape(2, -1).T + 0.5
    pts = np.column_stack([np.full(len(yz), 20.5), yz]).astype(np.float32)
    for _ in range(2):
        m.insert(pts, np.array([0.5, 0.5, 0.5]), stamp=4.0)
    return m


def test_occupancy_reports_unknown_distinctly(wall: VoxelMap) -> None:
    occ = wall.occupancy(np.array([[20.5, 0.5, 0.5], [10.5, 0.5, 0.5], [40.0, 0.0, 0.0], [np.nan, 0, 0]]))
    assert occ[0] == pytest.approx(0.8448, abs=1e-3)  # two hits
    assert occ[1] == pytest.approx(0.3077, abs=1e-3)  # two misses
    assert np.isnan(occ[2]) and np.isnan(occ[3])


def test_raycast_finds_the_first_occupied_voxel(wall: VoxelMap) -> None:
    hit = wall.raycast(np.array([0.5, 0.5, 0.5]), np.array([1.0, 0.1, 0.0]))
    assert hit is not None and hit[0] == pytest.approx(20.5)
    assert wall.raycast(np.array([0.5, 0.5, 0.5]), np.array([-1.0, 0, 0])) is None
    assert wall.raycast(np.array([0.5, 0.5, 0.5]), np.array([1.0, 0, 0]), max_range=10) is None
    with pytest.raises(ValueError, match="direction"):
        wall.raycast(np.zeros(3), np.zeros(3))


def test_voxels_in_a_box(wall: VoxelMap) -> None:
    v = wall.voxels(np.array([19, -2, -2]), np.array([22, 2, 2]))
    assert len(v) == 16  # y, z in -2..1 (4 x 4) at x = 20
    assert np.all(v.centers[:, 0] == 20.5)
    assert np.all(v.last_seen == 4.0)
    free = wall.voxels(np.array([5, 0, 0]), np.array([7, 0.9, 0.9]), min_occupancy=0.0)
    assert len(free) == 2 and np.all(free.occupancy < 0.5)
    with pytest.raises(ValueError, match="box_min"):
        wall.voxels(np.array([1, 1, 1]), np.array([0, 0, 0]))


def test_occupied_is_octomaps_definition_everywhere() -> None:
    """A voxel exactly at the threshold (one hit, threshold = prob_hit) is occupied, as in OctoMap's
    isNodeOccupied (log-odds >= threshold), for voxels(), the column layers, raycast and stats."""
    m = VoxelMap(1.0, occupied_threshold=0.7)
    m.insert(np.array([[5.5, 0.5, 0.5]]), np.array([0.5, 0.5, 0.5]))
    assert m.occupancy(np.array([[5.5, 0.5, 0.5]]))[0] == pytest.approx(0.7)
    np.testing.assert_array_equal(m.voxels(np.full(3, -9.0), np.full(3, 9.0)).centers, [[5.5, 0.5, 0.5]])
    assert m.column_layers(5.0, 0.0, 1, 1).observed[0, 0]
    np.testing.assert_array_equal(m.raycast(np.array([0.5, 0.5, 0.5]), np.array([1.0, 0, 0])), [5.5, 0.5, 0.5])
    assert m.stats()["occupied_leaves"] == 1


def test_a_voxel_at_the_upper_bound_keeps_its_attributes_current() -> None:
    """Its occupancy no longer changes (OctoMap's clamping), but every hit updates time, distance and color."""
    m = VoxelMap(1.0)
    for t in range(10):
        m.insert(np.array([[5.5, 0.5, 0.5]]), np.array([0.05 + 0.1 * t, 0.5, 0.5]), np.array([[t, 2 * t, 3 * t]], np.uint8), stamp=t)
    assert m.occupancy(np.array([[5.5, 0.5, 0.5]]))[0] == pytest.approx(0.971, abs=1e-3)
    v = m.voxels(np.full(3, -9.0), np.full(3, 9.0))
    assert v.last_seen.tolist() == [9.0] and v.color.tolist() == [[9, 18, 27]]
    assert v.min_distance[0] == pytest.approx(5.5 - 0.95)  # the nearest: the last, from x = 0.95
    cols = m.column_layers(5.0, 0.0, 1, 1)
    assert cols.last_seen[0, 0] == 9.0


def test_readers_run_safely_while_frames_are_inserted() -> None:
    frames = survey_clouds(4, seed=2, width=200, height=150)
    m = VoxelMap(1.0)
    errors: list[BaseException] = []
    reads = [0]
    done = threading.Event()

    def reader() -> None:
        try:
            while not done.is_set():
                cl = m.column_layers(-150, -150, 300, 300)
                assert cl.observed.sum() == np.isfinite(cl.elevation).sum()
                m.stats()
                m.occupancy(np.zeros((100, 3)))
                reads[0] += 1
        except BaseException as exc:  # surfaced below
            errors.append(exc)

    threads = [threading.Thread(target=reader) for _ in range(2)]
    for t in threads:
        t.start()
    for f in frames:
        m.insert(f.points, f.origin, f.colors, f.stamp)
    done.set()
    for t in threads:
        t.join()
    assert not errors
    assert reads[0] > 0
    assert m.column_layers(-150, -150, 300, 300).observed.sum() > 3000
