"""MCDM decision maker: weighted layers, area of interest, distance ring, path history -> next waypoint."""

from layerpilot.decide.area import area_geometry, zone_mask
from layerpilot.decide.behavior import (
    Area,
    Behavior,
    Retarget,
    SchedulePhase,
    Terrain,
    behavior_from_dict,
    load_behavior,
    preset_names,
)
from layerpilot.decide.decision import Candidate, Decision
from layerpilot.decide.history import PathHistory
from layerpilot.decide.maker import DecisionMaker, distance_preference
from layerpilot.decide.schedule import WeightSchedule
from layerpilot.decide.terrain import terrain_altitude

__all__ = [
    "Area",
    "Behavior",
    "Candidate",
    "Decision",
    "DecisionMaker",
    "PathHistory",
    "Retarget",
    "SchedulePhase",
    "Terrain",
    "WeightSchedule",
    "area_geometry",
    "behavior_from_dict",
    "distance_preference",
    "load_behavior",
    "preset_names",
    "terrain_altitude",
    "zone_mask",
]
