"""Camera orientation in the map frame (ENU, OpenCV camera axes) from a photo's attitude angles.

Vendors give the gimbal's yaw (clockwise from north), pitch (-90 = nadir) and roll in NED,
for a gimbal whose x axis is the optical axis, y points right in the image and z down in it.
The camera frame (x right, y down, z forward) is that frame with its axes renamed, and ENU is
NED with x, y swapped and z negated.
"""

from __future__ import annotations

import math

import numpy as np

from layerpilot.geometry import Pose
from layerpilot.photos.metadata import PhotoMetadata

_NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_CAMERA_IN_GIMBAL = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # columns: camera x, y, z


def camera_rotation(yaw_deg: float, pitch_deg: float, roll_deg: float) -> np.ndarray:
    """3x3 rotation camera -> ENU of a camera with these NED gimbal angles (degrees)."""
    r = Pose.from_euler(math.radians(roll_deg), math.radians(pitch_deg), math.radians(yaw_deg)).rotation
    return _NED_TO_ENU @ r @ _CAMERA_IN_GIMBAL


def camera_pose(meta: PhotoMetadata, position: np.ndarray) -> Pose:
    """The photo's camera pose: gimbal angles when it has them, else the flight attitude with the
    camera looking straight down; ValueError when the photo has neither."""
    if meta.gimbal_yaw is not None and meta.gimbal_pitch is not None:
        angles = (meta.gimbal_yaw, meta.gimbal_pitch, meta.gimbal_roll or 0.0)
    elif meta.flight_yaw is not None:
        angles = (meta.flight_yaw, -90.0 + (meta.flight_pitch or 0.0), meta.flight_roll or 0.0)
    else:
        raise ValueError(f"{meta.path.name}: no gimbal or flight attitude in XMP")
    return Pose.from_rotation(camera_rotation(*angles), position)
