"""A camera calibration in OpenCV's YAML format (what ``cv2.calibrateCamera`` tools write).

Keys: ``camera_matrix`` (3x3), ``distortion_coefficients`` (1xN, optional), ``image_width``
and ``image_height``. It overrides the intrinsics guessed from EXIF; photos are undistorted
with it before anything else looks at them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from layerpilot.geometry import CameraIntrinsics


@dataclass(frozen=True)
class Calibration:
    intrinsics: CameraIntrinsics
    distortion: np.ndarray  # OpenCV's (k1, k2, p1, p2[, k3...]); zeros = none

    def undistort(self, image: np.ndarray) -> np.ndarray:
        if not np.any(self.distortion):
            return image
        return cv2.undistort(image, self.intrinsics.K, self.distortion)

    def for_size(self, width: int, height: int) -> "Calibration":
        """The calibration for photos of ``width`` x ``height``; ValueError if the aspect differs."""
        k = self.intrinsics
        if (width, height) == k.size:
            return self
        s = width / k.width
        if abs(height / k.height - s) > 1e-3:
            raise ValueError(f"calibration: made for {k.width}x{k.height}, photos are {width}x{height}")
        return Calibration(k.scaled(s), self.distortion)


def read_calibration(path: str | Path) -> Calibration:
    """Read an OpenCV YAML calibration; ValueError names the file and the missing or bad key."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: calibration file not found")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        K = fs.getNode("camera_matrix").mat()
        dist = fs.getNode("distortion_coefficients").mat()
        width, height = (int(fs.getNode(k).real()) for k in ("image_width", "image_height"))
    finally:
        fs.release()
    if K is None or K.shape != (3, 3):
        raise ValueError(f"{path}: camera_matrix missing or not 3x3")
    if width < 1 or height < 1:
        raise ValueError(f"{path}: image_width and image_height must be positive")
    dist = np.zeros(5) if dist is None else np.asarray(dist, np.float64).ravel()
    if not np.all(np.isfinite(dist)) or len(dist) not in (4, 5, 8, 12, 14):
        raise ValueError(f"{path}: distortion_coefficients must be 4, 5, 8, 12 or 14 finite numbers")
    try:
        return Calibration(CameraIntrinsics.from_K(K, width, height), dist)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
