"""A folder of geotagged photos -> camera frames in the map frame (local ENU at an origin).

The origin is a configured ``LocalFrame`` or the first photo's position with its height
above take-off removed (so z is the height above the take-off point when the photo says it).
Photos without a position, without an attitude or of another size than the first are reported
and skipped; a folder with no usable photo is an error.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from layerpilot.geodesy import LocalFrame
from layerpilot.geometry import CameraFrame, CameraIntrinsics
from layerpilot.photos.attitude import camera_pose
from layerpilot.photos.calibration import Calibration
from layerpilot.photos.metadata import PhotoMetadata, read_metadata

SUFFIXES = (".jpg", ".jpeg")


@dataclass
class PhotoFolder:
    """The usable photos of a folder, their metadata, and what was skipped and why."""

    origin: LocalFrame
    photos: list[PhotoMetadata]
    skipped: dict[str, str] = field(default_factory=dict)  # file name -> reason
    calibration: Calibration | None = None
    width: int = 1000  # working width of the frames

    def intrinsics(self, meta: PhotoMetadata) -> CameraIntrinsics:
        """The full-size camera of a photo: the calibration's, else EXIF's (principal point at the centre)."""
        if self.calibration is not None:
            return self.calibration.for_size(meta.width, meta.height).intrinsics
        f = meta.focal_px()
        return CameraIntrinsics(f, f, (meta.width - 1) / 2, (meta.height - 1) / 2, meta.width, meta.height)

    def position(self, meta: PhotoMetadata) -> np.ndarray:
        return np.array([float(c) for c in self.origin.from_geodetic(meta.lat, meta.lon, meta.alt)])

    def frame(self, index: int) -> CameraFrame:
        """Photo ``index`` as a frame at the working width (undistorted first if calibrated); stamp = index."""
        meta = self.photos[index]
        image = cv2.imread(str(meta.path), cv2.IMREAD_COLOR)
        if image is None:
            raise ValueError(f"{meta.path.name}: OpenCV cannot decode it")
        if (image.shape[1], image.shape[0]) != (meta.width, meta.height):
            raise ValueError(f"{meta.path.name}: EXIF says {meta.width}x{meta.height}, "
                             f"the image is {image.shape[1]}x{image.shape[0]}")
        if self.calibration is not None:
            image = self.calibration.for_size(meta.width, meta.height).undistort(image)
        scale = self.width / meta.width
        small = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        k = self.intrinsics(meta).scaled(scale)
        small = cv2.resize(small, k.size, interpolation=cv2.INTER_AREA) if small.shape[1::-1] != k.size else small
        return CameraFrame(np.ascontiguousarray(small[:, :, ::-1]), camera_pose(meta, self.position(meta)), k,
                           float(index))

    def frames(self) -> Iterator[CameraFrame]:
        return (self.frame(i) for i in range(len(self.photos)))


def take_off_origin(meta: PhotoMetadata) -> LocalFrame:
    """Below the photo at its take-off height (its GPS altitude minus its height above take-off)."""
    return LocalFrame(meta.lat, meta.lon, meta.alt - (meta.relative_altitude or 0.0))


def read_folder(folder: str | Path, origin: LocalFrame | None = None, calibration: Calibration | None = None,
                width: int = 1000) -> PhotoFolder:
    """Read every JPEG's metadata (sorted by name) and keep the ones that can be placed.

    ``folder`` holds the photos, or is a project folder with them in ``images/`` (as OpenDroneMap's).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"{folder}: not a folder")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in SUFFIXES)
    if not files and (folder / "images").is_dir():
        return read_folder(folder / "images", origin, calibration, width)
    if not files:
        raise ValueError(f"{folder}: no .jpg photos")
    photos: list[PhotoMetadata] = []
    skipped: dict[str, str] = {}
    for path in files:
        try:
            meta = read_metadata(path)
        except (OSError, ValueError) as exc:
            skipped[path.name] = str(exc)
            continue
        if not meta.has_position:
            skipped[path.name] = "no GPS position in EXIF"
        elif meta.gimbal_yaw is None and meta.flight_yaw is None:
            skipped[path.name] = "no gimbal or flight attitude in XMP"
        elif photos and (meta.width, meta.height) != (photos[0].width, photos[0].height):
            skipped[path.name] = f"size {meta.width}x{meta.height} differs from {photos[0].width}x{photos[0].height}"
        elif calibration is None and not (meta.sensor_width_mm or meta.focal_35mm):
            skipped[path.name] = "no sensor size or 35 mm focal length in EXIF and no calibration"
        else:
            photos.append(meta)
    if not photos:
        raise ValueError(f"{folder}: none of {len(files)} photos is usable: "
                         + "; ".join(f"{k}: {v}" for k, v in skipped.items()))
    return PhotoFolder(origin or take_off_origin(photos[0]), photos, skipped, calibration, width)
