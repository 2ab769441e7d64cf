"""Renderer: depth against an independent numpy ray cast, sky, texture, camera pose math."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerpilot.camera import CameraConfig, camera_pose, pixel_rays
from layerpilot.sim import Renderer, World, WorldConfig

WORLD = WorldConfig(seed=11, size=120.0, trees_per_hectare=300.0, clearings=2, tile_size=30.0)


@pytest.fixture(scope="module")
def world() -> World:
    return World(WORLD)


@pytest.fixture(scope="module")
def renderer(world):
    r = Renderer(world, CameraConfig())
    yield r
    r.close()


def _ray_cast(world: World, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Nearest hit distance along each unit ray (Moller-Trumbore over every triangle), inf when none."""
    p = world.vertices[world.triangles].astype(np.float64)
    a, e1, e2 = p[:, 0], p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    s = origin - a
    q = np.cross(s, e1)
    out = np.full(len(dirs), np.inf)
    for k, d in enumerate(dirs):
        h = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, h)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        u = np.einsum("ij,ij->i", s, h) * inv
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6)
        if hit.any():
            out[k] = t[hit].min()
    return out


@pytest.mark.parametrize("position, yaw, pitch", [((5.0, -3.0, 35.0), 0.7, 60.0), ((-20.0, 10.0, 25.0), 2.5, 20.0)])
def test_rendered_depth_matches_independent_ray_cast(world, renderer, position, yaw, pitch):
    pose = camera_pose(position, yaw, pitch)
    frame = renderer.render(pose)
    rng = np.random.default_rng(0)
    u = rng.integers(0, 640, 300)
    v = rng.integers(0, 480, 300)
    dirs = pixel_rays(frame.intrinsics, pose, u, v)
    dist = _ray_cast(world, pose.position, dirs)
    zdepth = dist * (dirs @ pose.rotation[:, 2])
    got = frame.depth[v, u].astype(np.float64)
    assert np.array_equal(np.isinf(got), np.isinf(zdepth))
    hit = np.isfinite(zdepth)
    assert hit.sum() > 100
    err = np.abs(got[hit] - zdepth[hit])
    assert err.max() < 0.01, f"max depth error {err.max():.4f} m at z up to {zdepth[hit].max():.1f} m"


def test_sky_is_inf_and_has_sky_colour(renderer):
    frame = renderer.render(camera_pose((0.0, 0.0, 40.0), 0.0, -10.0))  # looking 10 deg above the horizon
    sky = np.isinf(frame.depth)
    assert sky[:100].all()  # the top rows see only sky
    assert (~sky).sum() > 1000  # the hills and trees ahead are below the horizon
    assert np.all(frame.image[sky] == np.array([160, 196, 235], np.uint8))


def test_colour_image_is_textured_not_flat(renderer, world):
    frame = renderer.render_vehicle((0.0, 0.0, float(world.terrain_height(0, 0)) + 30.0), 0.0)
    assert frame.image.shape == (480, 640, 3) and frame.image.dtype == np.uint8
    assert frame.depth.shape == (480, 640) and frame.depth.dtype == np.float32
    assert np.isfinite(frame.depth).all()
    gray = frame.image.astype(np.float64).mean(axis=2)
    # high-frequency texture: neighbouring pixels differ, and every 16x16 block has variance
    assert np.mean(np.abs(np.diff(gray, axis=1))) > 2.0
    blocks = gray.reshape(30, 16, 40, 16).std(axis=(1, 3))
    assert np.percentile(blocks, 10) > 2.0


def test_camera_pose_math():
    cam = CameraConfig()
    K = cam.intrinsics.K
    assert K[0, 0] == pytest.approx(320.0) and K[1, 1] == pytest.approx(320.0)  # 90 deg HFOV at 640 px
    assert (K[0, 2], K[1, 2]) == (319.5, 239.5)
    pose = camera_pose((1.0, 2.0, 30.0), math.pi / 2, 60.0)  # yaw north
    R = pose.rotation
    assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    # optical axis: north and 60 deg down; image x axis: east; image y axis: down-ish, toward -north
    assert np.allclose(R[:, 2], [0.0, 0.5, -math.sqrt(3) / 2], atol=1e-12)
    assert np.allclose(R[:, 0], [1.0, 0.0, 0.0], atol=1e-12)
    assert np.allclose(R[:, 1], [0.0, -math.sqrt(3) / 2, -0.5], atol=1e-12)
    # the ground point the optical axis hits is 30/tan(60) m north, at the principal point
    target = np.array([1.0, 2.0 + 30.0 / math.tan(math.radians(60)), 0.0])
    pc = pose.to_local(target[None])[0]
    uv = K @ pc / pc[2]
    assert np.allclose(uv[:2], [319.5, 239.5])
    assert pc[2] == pytest.approx(30.0 / math.sin(math.radians(60)))
    # a point east of the target appears right of centre
    pe = pose.to_local((target + [5.0, 0, 0])[None])[0]
    assert (K @ pe / pe[2])[0] > 319.5
    with pytest.raises(ValueError, match="position"):
        camera_pose((0.0, 0.0), 0.0)


def test_render_rejects_bad_pose(renderer):
    with pytest.raises(ValueError, match="pose"):
        renderer.render(np.eye(4))


def test_rendered_frame_is_stamped_with_pose_and_intrinsics(renderer):
    pose = camera_pose((0.0, 0.0, 40.0), 0.3, 60.0)
    frame = renderer.render(pose, stamp=12.5)
    assert frame.stamp == 12.5 and frame.pose == pose and frame.intrinsics == CameraConfig().intrinsics
