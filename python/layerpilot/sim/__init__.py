"""Simulator: procedural forest world, the camera rendered with ground-truth depth (the camera model itself
is ``layerpilot.camera``), the simulated multicopter.

The vehicle dynamics and its MAVLink endpoint live in ``vehicle`` and
``mavlink_vehicle``; ``simulator`` ties world, camera and vehicle together; ``sensors``
states how far what the drone reports is from the truth.
Rendering needs moderngl and is imported lazily. See docs/sim.md.
"""

from layerpilot.sim.world import World, WorldConfig


_LAZY = {"Renderer": "render", "Simulator": "simulator", "SimConfig": "simulator"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f"layerpilot.sim.{_LAZY[name]}"), name)
    raise AttributeError(name)


__all__ = ["Renderer", "SimConfig", "Simulator", "World", "WorldConfig"]
