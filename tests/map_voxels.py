"""Two voxel maps compared voxel by voxel, exactly: the same voxels known, the same ones occupied."""

from __future__ import annotations

import numpy as np

from layerpilot.bench.map import all_voxels, voxel_keys
from layerpilot.map import VoxelMap


def known_and_occupied(m: VoxelMap) -> tuple[np.ndarray, np.ndarray]:
    """Sorted keys of every voxel the map knows, and of those occupied (OctoMap's isNodeOccupied)."""
    s = m.stats()
    occupied = m.voxels(np.array(s["bounds_min"]), np.array(s["bounds_max"])).centers
    return np.sort(voxel_keys(all_voxels(m)[0], m.resolution)), np.sort(voxel_keys(occupied, m.resolution))


def assert_same_occupancy(a: VoxelMap, b: VoxelMap) -> int:
    """Both maps know the same voxels and call the same ones occupied; returns how many they know."""
    (known_a, occupied_a), (known_b, occupied_b) = known_and_occupied(a), known_and_occupied(b)
    np.testing.assert_array_equal(known_a, known_b, err_msg="known voxels")
    np.testing.assert_array_equal(occupied_a, occupied_b, err_msg="occupied voxels")
    return len(known_a)
