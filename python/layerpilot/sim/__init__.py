"""Simulator: procedural forest world, rendered camera with ground-truth depth, scripted baselines.

The vehicle dynamics and its MAVLink endpoint live in ``vehicle`` and
``mavlink_vehicle``; rendering needs moderngl and is imported lazily.
"""

from layerpilot.sim.camera import CameraConfig, CameraPose, camera_pose, pixel_rays
from layerpilot.sim.world import World, WorldConfig


def __getattr__(name: str):
    if name in ("Renderer", "Frame"):
        from layerpilot.sim import render

        return getattr(render, name)
    raise AttributeError(name)


__all__ = ["CameraConfig", "CameraPose", "Frame", "Renderer", "World", "WorldConfig", "camera_pose", "pixel_rays"]
