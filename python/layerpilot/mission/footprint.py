"""What a camera sees of flat ground from a height: the sizes survey planning derives lines and speeds from.

Every length is horizontal, in metres, for a camera pitched ``camera.pitch_deg`` below the
horizon at ``height`` metres above the ground. "Across" is the image's horizontal direction,
"band" the stretch of ground along the camera's look direction, from its near to its far edge.
"""

from __future__ import annotations

import math

from layerpilot.camera import CameraConfig


def _check(camera: CameraConfig, height: float) -> None:
    if not height > 0:
        raise ValueError(f"height_above_ground must be > 0, got {height}")
    if camera.pitch_deg <= 0:
        raise ValueError(f"the camera must look down for a ground footprint, pitch_deg = {camera.pitch_deg}")


def slant_range(camera: CameraConfig, height: float) -> float:
    """Distance from the camera to the ground along the optical axis."""
    _check(camera, height)
    return height / math.sin(math.radians(camera.pitch_deg))


def vertical_fov_deg(camera: CameraConfig) -> float:
    """The vertical field of view of square pixels with the camera's horizontal one."""
    half = math.atan(math.tan(math.radians(camera.hfov_deg) / 2) * camera.height / camera.width)
    return math.degrees(2 * half)


def footprint_width(camera: CameraConfig, height_above_ground: float) -> float:
    """Width across the image of the ground seen by the image's centre row.

    The centre row's rays lie in a plane through the optical axis; it meets the ground at the
    slant range, where the image spans 2 tan(hfov/2) per metre of range.
    """
    return 2.0 * slant_range(camera, height_above_ground) * math.tan(math.radians(camera.hfov_deg) / 2)


def view_band(camera: CameraConfig, height: float, max_range: float) -> tuple[float, float]:
    """(near, far): where the image's bottom and top rows meet the ground, along the look direction.

    Measured from below the camera; ``near`` < 0 when the bottom row looks behind the vertical
    (a nadir camera: -far). ``far`` ends at the ground reach of ``max_range`` (the farthest a
    map keeps a point), as does a top row at or above the horizon.
    """
    _check(camera, height)
    if not max_range > height:
        raise ValueError(f"max_range must exceed the height, got {max_range} <= {height}")
    reach = math.sqrt(max_range**2 - height**2)
    half = vertical_fov_deg(camera) / 2
    steep, shallow = math.radians(camera.pitch_deg + half), math.radians(camera.pitch_deg - half)
    near = height / math.tan(steep)
    far = height / math.tan(shallow) if shallow > 0 else math.inf
    return max(near, -reach), min(far, reach)


def survey_speed(camera: CameraConfig, height_above_ground: float, frame_rate_hz: float,
                 baseline_ratio: float) -> float:
    """Ground speed (m/s) at which consecutive frames are ``baseline_ratio`` x the slant range apart.

    Survey planners derive speed from the trigger rate and the overlap they need; for
    two-view stereo the need is a baseline, relative to the slant range to the ground
    at the image centre. Faster, and frames are too far apart to pair; slower wastes time.
    """
    if not frame_rate_hz > 0 or not baseline_ratio > 0:
        raise ValueError(f"frame_rate_hz and baseline_ratio must be > 0, got {frame_rate_hz}, {baseline_ratio}")
    return baseline_ratio * slant_range(camera, height_above_ground) * frame_rate_hz
