"""What one cloud may cost the map service is bounded before it is inserted: the ray length, the volume it
may reach, the voxel steps of its rays and the map's size. The clouds that took the map server down
(max_range = 1e7, points over +-5 km) cost a few MB and a fraction of a second."""

from __future__ import annotations

import time

import numpy as np
import pytest

from layerpilot.mission.build import map_volume
from layerpilot.missionfile import load_mission
from layerpilot.mission.map_service import MAX_RAY_STEPS, CloudRefused, MapService, MapServiceConfig, Volume

ORIGIN = np.array([0.0, 0.0, 50.0])
rng = np.random.default_rng(3)


def service(volume: Volume | None = None, **cfg) -> MapService:
    return MapService(MapServiceConfig(snapshot="", **cfg), volume=volume)


def far_cloud(n: int) -> np.ndarray:
    """``n`` points uniform over +-5 km: the hostile cloud (10,000 points are 120 KB on the bus)."""
    return rng.uniform(-5000, 5000, (n, 3)).astype(np.float32)


def test_a_cloud_max_range_only_lowers_the_services():
    point = np.array([[1000.0, 0.0, 50.0]], np.float32)  # one ray along +x, far beyond every range
    for asked, reach in ((1e7, 100.0), (None, 100.0), (40.0, 40.0)):
        s = service(max_range=100.0)
        s.insert(point, ORIGIN, None, 1.0, asked)
        assert s.map.stats()["bounds_max"][0] == pytest.approx(reach, abs=1.0), asked


def test_the_120_kb_cloud_costs_little_and_leaves_the_map_intact():
    """10,000 points over +-5 km with max_range = 1e7: 120 KB on the bus, nearly all of it outside the area."""
    s = service(map_volume(load_mission("default").core))
    honest = rng.uniform([-30, -30, 0], [30, 30, 5], (5000, 3)).astype(np.float32)
    s.insert(honest, ORIGIN, None, 1.0, 100.0)
    before = s.map.stats()
    t = time.perf_counter()
    result = s.insert(far_cloud(10_000), ORIGIN, None, 2.0, 1e7)
    took = time.perf_counter() - t
    after = s.map.stats()
    assert s.points_outside > 9_900  # the volume is +-220 m: about 0.2 % of the points fall in it
    assert result.points_used == 10_000 - s.points_outside
    assert took < 1.0, took
    assert after["total_bytes"] - before["total_bytes"] < 5e6, (before, after)
    assert after["occupied_leaves"] >= before["occupied_leaves"]  # nothing the honest cloud mapped is lost
    assert np.all(np.abs(after["bounds_max"]) <= 220 + 1)


def test_without_a_volume_the_ray_cap_alone_bounds_the_cloud():
    s = service()
    t = time.perf_counter()
    s.insert(far_cloud(10_000), ORIGIN, None, 1.0, 1e7)
    assert time.perf_counter() - t < 2.0
    stats = s.map.stats()
    assert np.all(np.abs(np.array(stats["bounds_max"]) - ORIGIN) <= 101)
    assert stats["total_bytes"] < 60e6, stats  # at most a 100 m ball at 1 m


def test_an_origin_outside_the_volume_is_refused_and_the_map_unchanged():
    s = service(map_volume(load_mission("default").core))
    with pytest.raises(CloudRefused, match="origin .* outside the mission's volume") as err:
        s.insert(np.zeros((10, 3), np.float32), np.array([5000.0, 0.0, 50.0]), None, 1.0)
    assert err.value.kind == "outside the area"
    assert s.map.stats()["leaves"] == 0 and s.clouds_inserted == 0


def test_a_cloud_over_the_ray_step_limit_is_refused_before_insertion():
    s = service(resolution=0.1)  # 1 M rays of 100 m at 0.1 m are 1e9 steps
    d = rng.normal(size=(1 << 20, 3))
    points = (ORIGIN + 150 * d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    t = time.perf_counter()
    with pytest.raises(CloudRefused, match=f"more than {MAX_RAY_STEPS}") as err:
        s.insert(points, ORIGIN, None, 1.0)
    assert err.value.kind == "too costly" and time.perf_counter() - t < 2.0
    assert s.map.stats()["leaves"] == 0
    s.insert(points[:1000], ORIGIN, None, 1.0)  # 1e6 steps: taken
    assert s.clouds_inserted == 1


def test_a_full_map_refuses_clouds_and_keeps_serving(monkeypatch):
    monkeypatch.setattr("layerpilot.mission.map_service.MAP_SIZE_EVERY", 0.0)
    s = service(max_map_mb=1.0)
    s.insert(rng.uniform(-60, 60, (20_000, 3)).astype(np.float32) + ORIGIN.astype(np.float32), ORIGIN, None, 1.0)
    full = s.map.stats()
    assert full["total_bytes"] >= 1e6, full
    with pytest.raises(CloudRefused, match="max_map_mb = 1") as err:
        s.insert(np.array([[10.0, 0.0, 50.0]], np.float32), ORIGIN, None, 2.0)
    assert err.value.kind == "map full"
    assert s.map.stats()["total_bytes"] == full["total_bytes"] and s.clouds_inserted == 1
    assert s.columns().observed.any()  # the map still answers


def test_bad_shapes_are_named():
    with pytest.raises(ValueError, match="points, origin: expected shapes"):
        service().insert(np.zeros((4, 2), np.float32), ORIGIN, None, 1.0)


def test_the_costliest_legal_cloud_stays_within_the_map_servers_budget():
    """1 M points spread over the 100 m ball around the sensor: nearly every voxel one cloud may reach at
    1 m (4.2 M). docs/bus.md budgets the map server for one insert's scratch of at most 240 MB."""
    s = service()
    d = rng.normal(size=(1 << 20, 3))
    radii = 100.0 * rng.uniform(0, 1, (1 << 20, 1)) ** (1 / 3)
    points = (ORIGIN + radii * d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    colors = rng.integers(0, 255, (1 << 20, 3), dtype=np.uint8)
    t = time.perf_counter()
    s.insert(points, ORIGIN, colors, 1.0)
    took = time.perf_counter() - t
    stats = s.map.stats()
    print(f"1 M-point ball: {took:.2f} s, scratch {stats['insert_scratch_bytes'] / 1e6:.0f} MB, "
          f"map {stats['total_bytes'] / 1e6:.0f} MB")
    assert stats["insert_scratch_bytes"] < 240e6 and stats["total_bytes"] < 60e6, stats
    assert took < 15.0, took  # 2.4-2.9 s at load 4-12; the loop's stall limit is 30 s
