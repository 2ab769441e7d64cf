"""Scripted patterns: lawnmower and orbit waypoints over a circular area of interest.

Both return waypoints as a float64 array (N, 4) of ``x, y, z, yaw`` in the map
frame (ENU metres; yaw in radians counter-clockwise from east, the heading the
vehicle, and so the camera, should hold on the way to that waypoint). They are
flown by the mission core's ``Pilot``, through the same MAVLink path as the decision
maker's waypoints, live and in lock-step.
"""

from __future__ import annotations

import math

import numpy as np

from layerpilot.camera import CameraConfig


def _check_area(centre, radius: float, altitude: float) -> np.ndarray:
    c = np.asarray(centre, dtype=np.float64)
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise ValueError(f"centre must be (x, y), got {centre!r}")
    if not radius > 0:
        raise ValueError(f"radius must be > 0, got {radius}")
    if not math.isfinite(altitude):
        raise ValueError(f"altitude must be finite, got {altitude}")
    return c


def footprint_width(camera: CameraConfig, height_above_ground: float) -> float:
    """Width across the track of the ground seen by the image's centre row, over flat ground.

    The centre row's rays lie in a plane through the optical axis; it meets the
    ground at slant range h / sin(pitch), where the image spans 2 tan(hfov/2) per
    metre of range.
    """
    if not height_above_ground > 0:
        raise ValueError(f"height_above_ground must be > 0, got {height_above_ground}")
    if camera.pitch_deg <= 0:
        raise ValueError(f"the camera must look down for a ground footprint, pitch_deg = {camera.pitch_deg}")
    slant = height_above_ground / math.sin(math.radians(camera.pitch_deg))
    return 2.0 * slant * math.tan(math.radians(camera.hfov_deg) / 2)


def survey_speed(camera: CameraConfig, height_above_ground: float, frame_rate_hz: float,
                 baseline_ratio: float) -> float:
    """Ground speed (m/s) at which consecutive frames are ``baseline_ratio`` x the scene depth apart.

    Survey planners derive speed from the trigger rate and the overlap they need; for
    two-view stereo the need is a baseline, relative to the slant range to the ground
    at the image centre. Faster, and frames are too far apart to pair; slower wastes time.
    """
    if not frame_rate_hz > 0 or not baseline_ratio > 0:
        raise ValueError(f"frame_rate_hz and baseline_ratio must be > 0, got {frame_rate_hz}, {baseline_ratio}")
    slant = height_above_ground / math.sin(math.radians(camera.pitch_deg))
    return baseline_ratio * slant * frame_rate_hz


def lawnmower(centre, radius: float, altitude: float, camera: CameraConfig, height_above_ground: float,
              side_overlap: float = 0.3, heading: float = 0.0) -> np.ndarray:
    """Parallel lines across the disc, spaced by the footprint width times (1 - side_overlap).

    Lines run along ``heading`` (ENU rad), alternate direction (boustrophedon) and
    end where they meet the circle, so the vehicle turns at the edge. Each line
    contributes its start and end waypoint, both with the line's heading.
    """
    c = _check_area(centre, radius, altitude)
    if not 0.0 <= side_overlap < 1.0:
        raise ValueError(f"side_overlap must be in [0, 1), got {side_overlap}")
    spacing = footprint_width(camera, height_above_ground) * (1.0 - side_overlap)
    n = max(1, math.ceil(2 * radius / spacing))
    offsets = (np.arange(n) - (n - 1) / 2) * spacing
    offsets = offsets[np.abs(offsets) < radius]
    along = np.array([math.cos(heading), math.sin(heading)])
    across = np.array([-along[1], along[0]])
    rows = []
    for k, off in enumerate(offsets):
        half = math.sqrt(radius * radius - off * off)
        sign = 1.0 if k % 2 == 0 else -1.0
        yaw = heading if sign > 0 else heading + math.pi
        yaw = math.atan2(math.sin(yaw), math.cos(yaw))
        for s in (-sign * half, sign * half):
            x, y = c + off * across + s * along
            rows.append((x, y, altitude, yaw))
    return np.array(rows)


def orbit(centre, radius: float, altitude: float, step: float = 10.0, start=None) -> np.ndarray:
    """Fly to the edge of the disc, then once around it with the camera facing the centre.

    The first waypoint is the edge point nearest ``start`` (east of the centre if
    ``start`` is None or the centre itself); the rest follow the circle
    counter-clockwise at most ``step`` metres apart and close the loop. Yaw at
    every waypoint points at the centre.
    """
    c = _check_area(centre, radius, altitude)
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step}")
    phi0 = 0.0
    if start is not None:
        d = np.asarray(start, dtype=np.float64)[:2] - c
        if np.hypot(*d) > 1e-9:
            phi0 = math.atan2(d[1], d[0])
    n = max(3, math.ceil(2 * math.pi * radius / step))
    phi = phi0 + 2 * math.pi * np.arange(n + 1) / n
    x = c[0] + radius * np.cos(phi)
    y = c[1] + radius * np.sin(phi)
    yaw = np.arctan2(np.sin(phi + math.pi), np.cos(phi + math.pi))
    return np.column_stack([x, y, np.full(n + 1, altitude), yaw])


def path_length(waypoints: np.ndarray, start=None) -> float:
    """Horizontal length of the polyline through the waypoints (from ``start`` if given)."""
    p = np.asarray(waypoints, dtype=np.float64)[:, :2]
    if start is not None:
        p = np.vstack([np.asarray(start, dtype=np.float64)[:2], p])
    return float(np.sum(np.hypot(*np.diff(p, axis=0).T)))
