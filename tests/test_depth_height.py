"""Height registration on rendered depth: clouds whose reported height wanders are put back onto the
ground and trees the flight has already mapped; what cannot be fitted is counted, never guessed."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import pytest

from layerpilot.camera import CameraConfig
from layerpilot.depth.height_registration import HeightRegistration, HeightRegistrationConfig
from layerpilot.depth.source import GroundTruthDepth
from layerpilot.eval.fixtures import sideways_flight
from layerpilot.geometry import PointCloud, Pose
from layerpilot.sim import Renderer, World, WorldConfig


@pytest.fixture(scope="module")
def clouds() -> list[PointCloud]:
    """The true clouds of a 16-frame flight, 5 m a second at 45 m, from the renderer's depth."""
    with Renderer(World(WorldConfig()), CameraConfig(width=320, height=240, pitch_deg=60.0)) as r:
        frames = sideways_flight(r, (-60.0, 70.0), heading_deg=20.0, altitude=45.0, pitch_deg=60.0, speed=5.0,
                                 frames=16, period=1.0)
    source = GroundTruthDepth(100.0, stride=2)
    return [source.push(f) for f in frames]


def _lifted(cloud: PointCloud, dz: float) -> PointCloud:
    return PointCloud(cloud.points + np.float32([0.0, 0.0, dz]), cloud.origin + (0.0, 0.0, dz), cloud.stamp,
                      cloud.colors)


def test_a_wandering_height_is_taken_out_cloud_by_cloud(clouds):
    """The reported height wanders 0.3 m a second (3 m over the flight, as a consumer GNSS and
    barometer do): every registered cloud comes back within 5 cm of its true height."""
    registration = HeightRegistration()
    wander = [0.3 * k for k in range(len(clouds))]
    out = [registration.register(_lifted(c, dz)) for c, dz in zip(clouds, wander)]
    errors = [float(np.median(o.points[:, 2] - c.points[:, 2])) for o, c in zip(out, clouds)]
    assert abs(errors[-1]) < 0.05, errors  # uncorrected: 4.5 m
    assert max(abs(e) for e in errors) < 0.05, errors
    stats = registration.stats()
    assert stats["height_registered"] == len(clouds) - 1 and stats["height_skipped_first_cloud"] == 1
    # the trajectory the clouds show is lifted by the same correction
    poses = registration.corrected([(c.stamp, Pose(c.origin)) for c in out])
    assert poses[-1][1].position[2] - out[-1].origin[2] == pytest.approx(registration.correction)
    lift = [p.position[2] for _, p in registration.corrected([(out[3].stamp + dt, Pose()) for dt in (0.0, 0.4, 0.6)])]
    assert lift[0] == lift[1] != lift[2]  # the nearest cloud's correction (clouds are 1 s apart)


def test_a_jump_or_a_cloud_over_unmapped_ground_keeps_the_last_correction_and_is_counted(clouds):
    registration = HeightRegistration()
    registration.register(clouds[0])
    jumped = registration.register(_lifted(clouds[1], 3.0))  # 3 m in a second: not GNSS's wander
    assert registration.stats()["height_skipped_step_too_large"] == 1
    assert float(np.median(jumped.points[:, 2] - clouds[1].points[:, 2])) == pytest.approx(3.0, abs=1e-4)
    far = PointCloud(clouds[2].points + np.float32([500.0, 0.0, 0.0]), clouds[2].origin + (500.0, 0.0, 0.0),
                     clouds[2].stamp)
    registration.register(far)
    stats = registration.stats()
    assert stats["height_skipped_too_few_matches"] == 1 and stats["height_registered"] == 0
    assert registration.correction == 0.0


def test_the_local_map_forgets_what_lies_beyond_its_radius(clouds):
    config = dataclasses.replace(HeightRegistrationConfig(), radius=30.0, tile=8.0)
    registration = HeightRegistration(config)
    for c in clouds:
        registration.register(c)
    kept = registration._near(np.full(3, -1e4), np.full(3, 1e4))  # every tile
    assert 0 < len(kept) == registration.stats()["height_map_points"]
    # whole tiles leave: none whose centre is beyond radius + one tile
    assert np.hypot(*(kept[:, :2] - clouds[-1].origin[:2]).T).max() <= 30.0 + 8.0 * (1 + 0.5 * 2 ** 0.5)


def test_settings_are_validated():
    with pytest.raises(ValueError, match="height_registration.max_step"):
        HeightRegistrationConfig(max_step=0.0)


def test_the_surface_check_refuses_a_cloud_that_jumps_and_takes_a_lasting_shift_once_most_clouds_share_it(clouds):
    """Clouds a second apart that wander by decimetres pass; one 3 m off is refused and cannot outvote the
    true ones (the next true cloud passes); a cloud over unmapped ground has nothing to compare and passes;
    a lasting 3 m shift is refused until most clouds of the check's memory share it, then taken."""
    from layerpilot.depth.surface_check import SurfaceCheck, SurfaceCheckConfig

    check = SurfaceCheck(SurfaceCheckConfig(memory=3.0))
    assert check.accepts(clouds[0]) and not np.isfinite(check.last_jump)  # nothing before it
    assert check.accepts(_lifted(clouds[1], 0.3)) and check.last_jump == pytest.approx(0.3, abs=0.05)
    assert not check.accepts(_lifted(clouds[2], 3.0))
    assert check.last_jump == pytest.approx(3.0, abs=0.05)  # against the (lower) median of clouds 0 and 1
    assert check.accepts(clouds[3]) and abs(check.last_jump) < 0.35  # the median of 0, 0.3 and 3 m: 0.3 m
    assert check.accepts(_lifted(clouds[3], -1.5), lift=1.5)  # the height correction it is about to get
    far = PointCloud(clouds[4].points + np.float32([500.0, 0.0, 0.0]), clouds[4].origin + (500.0, 0.0, 0.0),
                     clouds[4].stamp)
    assert check.accepts(far) and not np.isfinite(check.last_jump)
    shifted = [check.accepts(_lifted(c, 3.0)) for c in clouds[5:12]]
    assert shifted == [False, False, True, True, True, True, True]  # 7: its memory holds only shifted clouds
    stats = check.stats()
    assert (stats["surface_checked"], stats["surface_refused"], stats["surface_accepted_inconsistent"]) == (11, 3, 0)


def test_the_surface_check_says_when_the_clouds_it_accepts_disagree_by_metres(clouds, caplog):
    """Clouds that each pass (1.7 m from the one before, under the 2 m limit) yet disagree by a median
    1.7 m make a map metres off: the check warns once and counts them; decimetres of disagreement do not."""
    from layerpilot.depth.surface_check import SurfaceCheck, SurfaceCheckConfig

    config = SurfaceCheckConfig(memory=1.0, consistency_clouds=6)  # the reference: the cloud a second before
    steady, wandering = SurfaceCheck(config), SurfaceCheck(config)
    with caplog.at_level(logging.WARNING, logger="layerpilot.depth"):
        assert all(steady.accepts(_lifted(c, 0.3 * (k % 2))) for k, c in enumerate(clouds))
        assert all(wandering.accepts(_lifted(c, 1.7 * (k % 2))) for k, c in enumerate(clouds))
    assert steady.stats()["surface_jump_median_m"] == pytest.approx(0.3, abs=0.05)
    assert steady.stats()["surface_accepted_inconsistent"] == 0
    stats = wandering.stats()
    assert stats["surface_refused"] == 0 and stats["surface_jump_median_m"] == pytest.approx(1.7, abs=0.05)
    # from the first compared cloud on, every one is counted (its median over the last six is 1.7 m)
    assert stats["surface_accepted_inconsistent"] == stats["surface_checked"] == len(clouds) - 1
    warnings = [r for r in caplog.records if "disagree" in r.getMessage()]
    assert len(warnings) == 1 and "1.7 m" in warnings[0].getMessage()


def test_a_clouds_surface_is_its_highest_point_per_cell():
    """Per plan cell the highest point, cells in key order; an empty cloud has no surface."""
    from layerpilot.depth.surface_check import surface

    points = np.array([[0.5, 0.5, 3.0], [0.2, 0.1, 5.0], [3.0, 3.0, 1.0], [0.9, 0.9, -2.0], [3.5, 3.9, 0.5]],
                      np.float32)
    keys, heights = surface(points, 1.0)
    assert len(keys) == 2 and np.all(np.diff(keys) > 0)
    assert sorted(heights.tolist()) == [1.0, 5.0]
    keys, heights = surface(np.zeros((0, 3), np.float32), 1.0)
    assert len(keys) == len(heights) == 0
