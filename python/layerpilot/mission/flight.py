"""Stereo-aware flight settings from the mission's camera: cruise speed, hop radii, camera view.

A behavior's ``[flight]`` table may ask for ``speed = "survey"`` and ``hops = "footprint"``;
both are derived here from the camera the mission flies, so they follow the altitude, pitch,
field of view, frame rate and image width instead of fixed metres.
"""

from __future__ import annotations

import dataclasses
import math

from layerpilot.decide.behavior import Behavior
from layerpilot.layers.view_gain import CameraView
from layerpilot.mission.heading import HeadingPolicy
from layerpilot.mission.footprint import footprint_width, survey_speed, vertical_fov_deg
from layerpilot.camera import CameraConfig


def footprint_hops(camera: CameraConfig, height: float, max_range: float) -> tuple[float, float]:
    """(r_e, r_i) from the ground footprint.

    r_e = a quarter of the footprint's width at the image centre: a hop moves the view by a
    quarter of itself at least, so a decision is worth its flight (fixed 10 m hops at 50 m
    moved a 115 m wide view by less than a tenth). r_i = r_e + twice the ground reach (the
    farthest ground the map keeps, sqrt(max_range^2 - height^2)): preference falls gently over
    a whole footprint length, so a far view that sees much more still wins over a near one.
    """
    if not max_range > height:
        raise ValueError(f"max_range must exceed the height, got {max_range} <= {height}")
    r_e = footprint_width(camera, height) / 4
    return r_e, r_e + 2 * math.sqrt(max_range**2 - height**2)


def camera_view(behavior: Behavior, heading: HeadingPolicy, camera: CameraConfig, max_range: float) -> CameraView:
    """What the view_gain layer assumes about the camera at a candidate under this behavior."""
    return CameraView(behavior.altitude, camera.pitch_deg, camera.hfov_deg, vertical_fov_deg(camera), max_range,
                      heading=behavior.flight.heading, yaw=heading.fixed_yaw, center=heading.center)


def flight_behavior(behavior: Behavior, camera: CameraConfig, max_range: float) -> Behavior:
    """The behavior with footprint hop radii when its ``[flight] hops = "footprint"``."""
    if behavior.flight.hops != "footprint":
        return behavior
    r_e, r_i = footprint_hops(camera, behavior.altitude, max_range)
    return dataclasses.replace(behavior, r_e=r_e, r_i=r_i)


def cruise_speed(behavior: Behavior, camera: CameraConfig, frame_rate_hz: float, baseline_ratio: float,
                 configured: float) -> float:
    """``configured`` (decide.speed) unless the behavior asks for the survey speed and none is configured."""
    if behavior.flight.speed == "survey" and configured == 0.0:
        return survey_speed(camera, behavior.altitude, frame_rate_hz, baseline_ratio)
    return configured
