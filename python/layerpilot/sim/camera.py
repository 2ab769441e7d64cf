"""Pinhole camera on the drone: intrinsics K and the camera pose from the vehicle pose.

Conventions (OpenCV):
  * camera frame: x right, y down, z forward along the optical axis;
  * pixel (u, v) = (column, row), the centre of the top-left pixel is (0, 0);
    a point p_c in the camera frame projects to ``K @ p_c / p_c[2]``;
  * ``CameraPose.rotation`` is R_map_cam (columns = camera axes in the map frame,
    maps camera-frame vectors to map-frame vectors) and ``CameraPose.centre`` is
    the optical centre in the map frame (ENU metres), so a map point X has camera
    coordinates ``R.T @ (X - centre)``;
  * vehicle yaw is ENU: radians counter-clockwise from +x (east), so yaw 0 looks
    east and pi/2 looks north. The camera sits at the vehicle position, yaw
    follows the vehicle, pitched ``pitch_deg`` below the horizon (no roll).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from layerpilot.config import check_range


@dataclass(frozen=True)
class CameraConfig:
    """Image size in pixels, horizontal field of view and mount pitch in degrees, clip range in metres."""

    width: int = 640
    height: int = 480
    hfov_deg: float = 90.0
    pitch_deg: float = 60.0
    near: float = 0.1
    far: float = 2000.0

    def __post_init__(self) -> None:
        check_range("width", self.width, 16, 8192)
        check_range("height", self.height, 16, 8192)
        check_range("hfov_deg", self.hfov_deg, 1.0, 170.0)
        check_range("pitch_deg", self.pitch_deg, -90.0, 90.0)
        check_range("near", self.near, 1e-3, 100.0)
        check_range("far", self.far, self.near * 10, 1e6)

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix (float64): square pixels, principal point at the image centre."""
        f = (self.width / 2) / math.tan(math.radians(self.hfov_deg) / 2)
        return np.array([[f, 0.0, (self.width - 1) / 2], [0.0, f, (self.height - 1) / 2], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class CameraPose:
    """Rotation camera->map (3x3) and optical centre in the map frame (3,)."""

    rotation: np.ndarray
    centre: np.ndarray

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """Map-frame points (N, 3) to camera-frame points (N, 3)."""
        return (np.asarray(points, dtype=np.float64) - self.centre) @ self.rotation


def camera_pose(position: np.ndarray | tuple[float, float, float], yaw: float, pitch_deg: float = 60.0) -> CameraPose:
    """Pose of the camera on a vehicle at ``position`` (ENU) with ENU ``yaw`` (rad), pitched down by ``pitch_deg``."""
    position = np.asarray(position, dtype=np.float64)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise ValueError(f"position must be 3 finite numbers, got {position!r}")
    if not math.isfinite(yaw):
        raise ValueError(f"yaw must be finite, got {yaw}")
    th = math.radians(pitch_deg)
    forward = np.array([math.cos(yaw) * math.cos(th), math.sin(yaw) * math.cos(th), -math.sin(th)])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    down = np.cross(forward, right)
    return CameraPose(np.column_stack([right, down, forward]), position.copy())


def pixel_rays(K: np.ndarray, pose: CameraPose, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit map-frame directions (N, 3) of the rays through pixels (u, v)."""
    pix = np.stack([np.asarray(u, float), np.asarray(v, float), np.ones(np.shape(u))], axis=-1)
    d = pix @ np.linalg.inv(K).T @ pose.rotation.T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)
