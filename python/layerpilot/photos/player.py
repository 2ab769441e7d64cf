"""A folder of geotagged photos played as a live camera: frames on the mission clock, poses as telemetry.

Photo ``i``, taken at EXIF time ``T_i``, is on the mission clock at ``start + T_i - T_0`` (the
first photo's time ``T_0``). Its EXIF position and XMP attitude become the vehicle's pose
stream (body FLU -> map): the photo's camera pose with the camera's mount taken off, so that
the camera node, which interpolates the pose stream at a frame's stamp and puts the mount back
(``camera.gimbal = false``), places the photo where its metadata says, as it would a real
camera's frame. Photos without a capture time, or taken at the same time as an earlier one,
are skipped with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from layerpilot.geodesy import LocalFrame
from layerpilot.geometry import CameraFrame, Pose
from layerpilot.photos.attitude import camera_pose
from layerpilot.photos.calibration import Calibration
from layerpilot.photos.folder import PhotoFolder, read_folder


@dataclass
class PhotoPlayer:
    """The playable photos of a folder in capture order, each with its mission-clock stamp."""

    folder: PhotoFolder  # photos in capture order; ``skipped`` says why the others are not played
    stamps: np.ndarray  # (N,) mission seconds, strictly increasing
    mount: Pose  # camera (OpenCV axes) -> body FLU

    def __len__(self) -> int:
        return len(self.folder.photos)

    def camera_pose(self, index: int) -> Pose:
        """Where the photo's metadata puts its camera (camera -> map)."""
        meta = self.folder.photos[index]
        return camera_pose(meta, self.folder.position(meta))

    def body_pose(self, index: int) -> Pose:
        """The telemetry pose for photo ``index`` (body FLU -> map): its camera pose less the mount."""
        return self.camera_pose(index) @ self.mount.inverse()

    def frame(self, index: int) -> CameraFrame:
        """Photo ``index`` at the working width, stamped on the mission clock, placed by its metadata."""
        frame = self.folder.frame(index)
        return CameraFrame(frame.image, frame.pose, frame.intrinsics, float(self.stamps[index]))


def open_player(path: str | Path, mount: Pose, start: float = 0.0, calibration: Calibration | None = None,
                width: int = 1000, origin: LocalFrame | None = None) -> PhotoPlayer:
    """A photo folder (or a project folder holding ``images/``) ready to play; ValueError if nothing can be."""
    folder = read_folder(path, origin, calibration, width)
    timed = sorted((m for m in folder.photos if m.taken_at is not None), key=lambda m: m.taken_at)
    for meta in folder.photos:
        if meta.taken_at is None:
            folder.skipped[meta.path.name] = "no capture time in EXIF (DateTimeOriginal)"
    played = []
    for meta in timed:
        if played and meta.taken_at <= played[-1].taken_at:
            folder.skipped[meta.path.name] = f"taken at the same time as {played[-1].path.name}"
        else:
            played.append(meta)
    if not played:
        raise ValueError(f"{path}: no photo has a capture time in EXIF (DateTimeOriginal): nothing to play")
    folder.photos = played
    stamps = start + np.array([m.taken_at - played[0].taken_at for m in played], np.float64)
    return PhotoPlayer(folder, stamps, mount)
