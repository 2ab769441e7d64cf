"""The ground-floor types: pose, intrinsics, camera frame, point cloud."""

import math

import numpy as np
import pytest

from layerpilot.geometry import (CameraFrame, CameraIntrinsics, PointCloud, Pose, matrix_from_quat, quat_from_euler,
                                 quat_from_matrix)
from layerpilot.camera import CameraConfig, camera_pose

rng = np.random.default_rng(3)


def random_rotation() -> np.ndarray:
    q = rng.normal(size=4)
    return matrix_from_quat(q / np.linalg.norm(q))


def test_quaternion_matrix_round_trip_including_near_180_degrees() -> None:
    rotations = [random_rotation() for _ in range(200)]
    rotations += [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]), np.eye(3)]
    for yaw in np.linspace(-math.pi, math.pi, 13):
        for pitch in (-90.0, -10.0, 0.0, 45.0, 90.0):
            rotations.append(camera_pose((0.0, 0.0, 0.0), yaw, pitch).rotation)
    for R in rotations:
        q = quat_from_matrix(R)
        assert q[0] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-12
        np.testing.assert_allclose(matrix_from_quat(q), R, atol=1e-12)


def test_pose_matrix_round_trip_inverse_and_composition() -> None:
    a = Pose.from_rotation(random_rotation(), rng.normal(size=3) * 10)
    b = Pose.from_rotation(random_rotation(), rng.normal(size=3) * 10)
    np.testing.assert_allclose(Pose.from_matrix(a.matrix).matrix, a.matrix, atol=1e-12)
    np.testing.assert_allclose((a @ b).matrix, a.matrix @ b.matrix, atol=1e-12)
    np.testing.assert_allclose((a @ a.inverse()).matrix, np.eye(4), atol=1e-12)
    p = rng.normal(size=(5, 3))
    np.testing.assert_allclose(a.to_map(p), p @ a.rotation.T + a.position, atol=1e-12)
    np.testing.assert_allclose(a.to_local(a.to_map(p)), p, atol=1e-12)
    assert Pose.from_matrix(a.matrix) == Pose(a.position, -a.orientation)  # q and -q: one rotation, stored w >= 0


def test_euler_angles_and_yaw_are_zyx_enu() -> None:
    for roll, pitch, yaw in [(0.0, 0.0, 0.0), (0.1, -0.05, 2.0), (-0.3, 0.4, -2.9), (0.0, 0.0, math.pi / 2)]:
        pose = Pose.from_euler(roll, pitch, yaw, (1.0, 2.0, 3.0))
        Rz = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
        Ry = np.array([[math.cos(pitch), 0, math.sin(pitch)], [0, 1, 0], [-math.sin(pitch), 0, math.cos(pitch)]])
        Rx = np.array([[1, 0, 0], [0, math.cos(roll), -math.sin(roll)], [0, math.sin(roll), math.cos(roll)]])
        np.testing.assert_allclose(pose.rotation, Rz @ Ry @ Rx, atol=1e-12)
        np.testing.assert_allclose(pose.euler, (roll, pitch, yaw), atol=1e-12)
        assert pose.yaw == pytest.approx(yaw, abs=1e-12)
        np.testing.assert_allclose(quat_from_euler(roll, pitch, yaw), pose.orientation, atol=1e-12)
    north = Pose.from_euler(0.0, 0.0, math.pi / 2)
    np.testing.assert_allclose(north.rotation[:, 0], [0.0, 1.0, 0.0], atol=1e-12)  # body x (forward) points north


def test_camera_pose_follows_the_opencv_convention() -> None:
    pose = camera_pose((1.0, 2.0, 30.0), math.pi / 2, 60.0)  # vehicle heading north, camera 60 deg down
    R = pose.rotation
    np.testing.assert_allclose(R[:, 0], [1.0, 0.0, 0.0], atol=1e-12)  # camera x = right = east
    np.testing.assert_allclose(R[:, 2], [0.0, math.cos(math.radians(60)), -math.sin(math.radians(60))], atol=1e-12)
    assert R[2, 1] < 0  # camera y (image down) has a downward map component
    assert pose.yaw == pytest.approx(0.0, abs=1e-12)  # the camera's x axis (right) heads east
    intr = CameraConfig(width=64, height=48, hfov_deg=90.0).intrinsics
    uv, z = intr.project(pose.to_local(np.array([[1.0, 2.0 + 30.0 / math.tan(math.radians(60)), 0.0]])))
    np.testing.assert_allclose(uv[0], [intr.cx, intr.cy], atol=1e-9)  # the optical axis meets the ground there
    assert z[0] == pytest.approx(30.0 / math.sin(math.radians(60)))


def test_intrinsics_from_fov_K_scaled_and_rays() -> None:
    k = CameraIntrinsics.from_fov(640, 480, 90.0)
    assert (k.fx, k.fy, k.cx, k.cy, k.size) == (pytest.approx(320.0), pytest.approx(320.0), 319.5, 239.5, (640, 480))
    assert CameraIntrinsics.from_K(k.K, 640, 480) == k
    half = k.scaled(0.5)
    assert (half.size, half.fx, half.cx) == ((320, 240), pytest.approx(160.0), pytest.approx(159.5))
    u, v = np.array([0.0, 319.5, 639.0]), np.array([0.0, 239.5, 479.0])
    uv, z = k.project(k.rays(u, v) * 7.0)
    np.testing.assert_allclose(uv, np.column_stack([u, v]), atol=1e-9)
    np.testing.assert_allclose(z, 7.0)


def test_frame_and_cloud_hold_what_they_are_given() -> None:
    k = CameraIntrinsics.from_fov(8, 6, 60.0)
    image = np.zeros((6, 8, 3), np.uint8)
    f = CameraFrame(image, Pose(), k, 1.5, np.ones((6, 8), np.float32))
    assert f.image is image and f.size == (8, 6) and f.stamp == 1.5
    np.testing.assert_allclose(f.optical_axis, [0.0, 0.0, 1.0])
    c = PointCloud(np.zeros((4, 3), np.float32), [1.0, 2.0, 3.0], 2.0, np.zeros((4, 3), np.uint8))
    assert len(c) == 4 and c.origin.dtype == np.float64 and c.colors is not None
    assert PointCloud(np.zeros((0, 3), np.float32), np.zeros(3), 0.0).colors is None


@pytest.mark.parametrize("make, name", [
    (lambda: Pose([0.0, np.nan, 0.0]), "position"),
    (lambda: Pose(np.zeros(2)), "position"),
    (lambda: Pose(np.zeros(3), [1.0, 0.0, np.nan, 0.0]), "orientation"),
    (lambda: Pose(np.zeros(3), [2.0, 0.0, 0.0, 0.0]), "orientation"),
    (lambda: Pose.from_rotation(np.eye(3) * 2), "rotation"),
    (lambda: Pose.from_rotation(np.diag([1.0, 1.0, -1.0])), "rotation"),
    (lambda: Pose.from_matrix(np.eye(3)), "matrix"),
    (lambda: Pose.from_euler(0.0, math.nan, 0.0), "pitch"),
    (lambda: CameraIntrinsics(0.0, 1.0, 0.0, 0.0, 4, 4), "fx"),
    (lambda: CameraIntrinsics(1.0, 1.0, 0.0, 0.0, 0, 4), "width"),
    (lambda: CameraIntrinsics.from_fov(4, 4, 180.0), "hfov_deg"),
    (lambda: CameraFrame(np.zeros((6, 8, 3), np.float32), Pose(), CameraIntrinsics.from_fov(8, 6, 60), 0.0), "image"),
    (lambda: CameraFrame(np.zeros((6, 8), np.uint8), Pose(), CameraIntrinsics.from_fov(8, 6, 60), 0.0), "image"),
    (lambda: CameraFrame(np.zeros((6, 8, 3), np.uint8), np.eye(4), CameraIntrinsics.from_fov(8, 6, 60), 0.0), "pose"),
    (lambda: CameraFrame(np.zeros((6, 8, 3), np.uint8), Pose(), CameraIntrinsics.from_fov(8, 5, 60), 0.0),
     "intrinsics"),
    (lambda: CameraFrame(np.zeros((6, 8, 3), np.uint8), Pose(), CameraIntrinsics.from_fov(8, 6, 60), math.nan),
     "stamp"),
    (lambda: CameraFrame(np.zeros((6, 8, 3), np.uint8), Pose(), CameraIntrinsics.from_fov(8, 6, 60), 0.0,
                         np.ones((6, 8))), "depth"),
    (lambda: PointCloud(np.zeros((4, 3)), np.zeros(3), 0.0), "points"),
    (lambda: PointCloud(np.zeros((4, 2), np.float32), np.zeros(3), 0.0), "points"),
    (lambda: PointCloud(np.full((1, 3), np.nan, np.float32), np.zeros(3), 0.0), "points"),
    (lambda: PointCloud(np.zeros((4, 3), np.float32), [0.0, 0.0, np.inf], 0.0), "origin"),
    (lambda: PointCloud(np.zeros((4, 3), np.float32), np.zeros(3), 0.0, np.zeros((3, 3), np.uint8)), "colors"),
])
def test_bad_arguments_raise_value_error_naming_them(make, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        make()


def test_pose_arrays_are_read_only_copies() -> None:
    position = np.array([1.0, 2.0, 3.0])
    pose = Pose(position)
    position[0] = 9.0
    assert pose.position[0] == 1.0
    with pytest.raises(ValueError):
        pose.position[0] = 5.0
    with pytest.raises(ValueError):
        pose.rotation[0, 0] = 5.0
