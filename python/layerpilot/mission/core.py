"""What the mission core needs of a mission: its vehicles, the step objects' settings, the drone's camera.

The mission file (``layerpilot.missionfile``) also says how the bus, the link and the simulator are
set up; the core never sees those. ``Mission.core`` gives this view of a mission file, so the live
nodes, the lock-step evaluator and replay build their step objects from the same settings.
"""

from __future__ import annotations

from dataclasses import dataclass

from layerpilot.camera import CameraConfig
from layerpilot.link.geofence import Geofence
from layerpilot.mission.depth_service import DepthServiceConfig
from layerpilot.mission.map_service import MapServiceConfig
from layerpilot.mission.pilot import PilotConfig


@dataclass(frozen=True)
class MissionCore:
    """The core's settings of one mission."""

    vehicles: tuple[str, ...]
    map_server: MapServiceConfig
    depth: DepthServiceConfig
    decide: PilotConfig
    camera: CameraConfig  # the drone's camera: size, field of view, mount pitch
    frame_rate_hz: float  # camera frames per mission second
    gimbal: bool  # the camera keeps only the vehicle's heading (roll and pitch levelled)
    geofence: Geofence  # where the drone may fly: the clouds' volume follows from it
