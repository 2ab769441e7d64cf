"""Camera-frame points of a frame -> the frame's map-frame ``PointCloud``."""

from __future__ import annotations

import cv2
import numpy as np

from layerpilot.geometry import CameraFrame, PointCloud


def camera_points_to_cloud(frame: CameraFrame, cam_points: np.ndarray, colors: np.ndarray,
                           rotation: np.ndarray | None = None) -> PointCloud:
    """Map-frame cloud (origin = the camera centre, stamp = the frame's) from points in ``frame``'s
    camera, first rotated by ``rotation`` (3x3) if given."""
    R = frame.pose.rotation if rotation is None else frame.pose.rotation @ rotation
    affine = np.hstack([R, frame.pose.position[:, None]]).astype(np.float32)
    cam = np.ascontiguousarray(cam_points, np.float32).reshape(-1, 1, 3)
    points = cv2.transform(cam, affine).reshape(-1, 3) if len(cam) else np.zeros((0, 3), np.float32)
    return PointCloud(points, frame.pose.position, frame.stamp, np.ascontiguousarray(colors, np.uint8))
