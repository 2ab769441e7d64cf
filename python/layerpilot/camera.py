"""The drone's camera: its configuration (size, field of view, mount pitch) and its pose from the vehicle pose.

Conventions are those of ``layerpilot.geometry`` (OpenCV camera: x right, y down,
z forward; a camera ``Pose`` maps camera coordinates to the map frame, ENU metres).
Vehicle yaw is ENU: radians counter-clockwise from +x (east), so yaw 0 looks east
and pi/2 looks north. The camera sits at the vehicle position, yaw follows the
vehicle, pitched ``pitch_deg`` below the horizon (no roll).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from layerpilot.config import check_range
from layerpilot.geometry import CameraIntrinsics, Pose


MOUNT_PITCH_DEG = 60.0  # the camera's default mount: degrees below the horizon (90 = nadir), one for every camera


@dataclass(frozen=True)
class CameraConfig:
    """Image size in pixels, horizontal field of view and mount pitch in degrees, clip range in metres."""

    width: int = 640
    height: int = 480
    hfov_deg: float = 90.0
    pitch_deg: float = MOUNT_PITCH_DEG
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
    def intrinsics(self) -> CameraIntrinsics:
        """Square pixels, principal point at the image centre: fx = fy = (W/2)/tan(hfov/2), cx = (W-1)/2."""
        return CameraIntrinsics.from_fov(self.width, self.height, self.hfov_deg)


def camera_pose(position: np.ndarray | tuple[float, float, float], yaw: float, pitch_deg: float = MOUNT_PITCH_DEG) -> Pose:
    """Pose (camera -> map) of the camera on a vehicle at ``position`` (ENU) with ENU ``yaw`` (rad),
    pitched down by ``pitch_deg`` (90 = straight down)."""
    position = np.asarray(position, dtype=np.float64)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise ValueError(f"position must be 3 finite numbers, got {position!r}")
    if not math.isfinite(yaw):
        raise ValueError(f"yaw must be finite, got {yaw}")
    th = math.radians(pitch_deg)
    forward = np.array([math.cos(yaw) * math.cos(th), math.sin(yaw) * math.cos(th), -math.sin(th)])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    down = np.cross(forward, right)
    return Pose.from_rotation(np.column_stack([right, down, forward]), position)


def pixel_rays(intrinsics: CameraIntrinsics, pose: Pose, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit map-frame directions (N, 3) of the rays through pixels (u, v)."""
    d = intrinsics.rays(u, v) @ pose.rotation.T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)
