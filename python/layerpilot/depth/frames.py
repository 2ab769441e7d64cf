"""Camera frames in, point clouds out.

A ``Frame`` is what the camera stream delivers: a color image, the pose of the
camera in the map frame, the intrinsics and a mission-clock stamp; ``depth`` is
optional ground truth (simulator or RGB-D). Camera axes follow OpenCV
(x right, y down, z forward) so the geometry can go straight into OpenCV.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np


def _check(arr: object, name: str, dtype: type, shape: tuple[int | None, ...]) -> np.ndarray:
    a = np.asarray(arr)
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        want = "x".join("N" if s is None else str(s) for s in shape)
        raise ValueError(f"{name}: expected shape {want}, got {a.shape}")
    if a.dtype != dtype:
        raise ValueError(f"{name}: expected dtype {np.dtype(dtype).name}, got {a.dtype.name}")
    return a


@dataclass(frozen=True)
class Frame:
    """One camera image with its pose (map <- camera, 4x4), intrinsics K (3x3) and stamp (s)."""

    image: np.ndarray  # uint8 (H, W, 3) RGB
    pose: np.ndarray  # float64 (4, 4) map <- camera, OpenCV camera axes
    K: np.ndarray  # float64 (3, 3)
    stamp: float
    depth: np.ndarray | None = None  # float32 (H, W) z-depth in metres (ground truth), inf/NaN = none

    def __post_init__(self) -> None:
        img = _check(self.image, "image", np.uint8, (None, None, 3))
        object.__setattr__(self, "pose", _check(np.asarray(self.pose, np.float64), "pose", np.float64, (4, 4)))
        object.__setattr__(self, "K", _check(np.asarray(self.K, np.float64), "K", np.float64, (3, 3)))
        if not np.all(np.isfinite(self.pose)) or not np.allclose(self.rotation @ self.rotation.T, np.eye(3), atol=1e-6):
            raise ValueError("pose: rotation part is not orthonormal or has non-finite values")
        if self.K[0, 0] <= 0 or self.K[1, 1] <= 0:
            raise ValueError("K: focal lengths must be positive")
        if self.depth is not None:
            _check(self.depth, "depth", np.float32, img.shape[:2])

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels, OpenCV's order."""
        return self.image.shape[1], self.image.shape[0]

    @property
    def rotation(self) -> np.ndarray:
        return self.pose[:3, :3]

    @property
    def center(self) -> np.ndarray:
        """Camera centre in the map frame."""
        return self.pose[:3, 3]

    @property
    def axis(self) -> np.ndarray:
        """Optical axis (camera +z) in the map frame."""
        return self.pose[:3, 2]

    def project(self, points_map: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) and z-depth (N,) of map-frame points in this camera."""
        cam = (points_map - self.center) @ self.rotation
        z = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (cam[:, :2] / z[:, None]) * np.diag(self.K)[:2] + self.K[:2, 2]
        return uv, z


@dataclass(frozen=True)
class PointCloud:
    """Map-frame points ready for ``VoxelMap.insert(points, origin, colors, stamp)``."""

    points: np.ndarray  # float32 (N, 3)
    colors: np.ndarray  # uint8 (N, 3)
    origin: np.ndarray  # float64 (3,) sensor origin = camera centre of the newest frame
    stamp: float
    pixels: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float32))  # (N, 2) where each came from

    def __len__(self) -> int:
        return len(self.points)


def camera_points_to_cloud(frame: Frame, cam_points: np.ndarray, colors: np.ndarray, pixels: np.ndarray,
                           rotation: np.ndarray | None = None) -> PointCloud:
    """Map-frame cloud from points in ``frame``'s camera (first rotated by ``rotation`` if given)."""
    R = frame.rotation if rotation is None else frame.rotation @ rotation
    affine = np.hstack([R, frame.center[:, None]]).astype(np.float32)
    cam = np.ascontiguousarray(cam_points, np.float32).reshape(-1, 1, 3)
    points = cv2.transform(cam, affine).reshape(-1, 3) if len(cam) else np.zeros((0, 3), np.float32)
    return PointCloud(points, np.ascontiguousarray(colors, np.uint8), frame.center.copy(), frame.stamp,
                      np.asarray(pixels, np.float32))
