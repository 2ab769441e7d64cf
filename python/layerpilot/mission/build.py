"""Step objects from a mission's core settings: the one place where the pipeline (so every driver) gets them."""

from __future__ import annotations

import dataclasses

from layerpilot.mission import flight, patterns
from layerpilot.mission.heading import HeadingPolicy
from layerpilot.mission.core import MissionCore
from layerpilot.depth.config import preset_for
from layerpilot.mission.depth_service import DepthService
from layerpilot.mission.map_service import Volume
from layerpilot.mission.pilot import Pilot
from layerpilot.mission.replan import GapReplanner


def build_pilot(mission: MissionCore, vehicle: str | None = None) -> Pilot:
    """The pilot of ``vehicle`` (default: the mission's first): the decision maker, or a pattern with the lines,
    speed and mount its camera needs, at the vehicle's altitude layer (``PilotConfig.flown_behavior``)."""
    cfg = mission.decide
    camera, max_range = mission.camera, mission.depth.max_depth
    ratio = preset_for(camera.width).pick.target_baseline_ratio
    layer = mission.vehicles.index(vehicle) if vehicle is not None else 0
    behavior = flight.flight_behavior(cfg.flown_behavior(layer), camera, max_range)
    if not behavior.scripted:  # stereo-aware flight: the behavior's heading, survey speed and footprint hops
        speed = flight.cruise_speed(behavior, camera, mission.frame_rate_hz, ratio, cfg.speed)
        view = (flight.camera_view(behavior, HeadingPolicy(behavior, cfg.home), camera, max_range)
                if "view_gain" in behavior.layer_names else None)
        return Pilot(dataclasses.replace(cfg, speed=speed), behavior, seed=cfg.seed, view=view)
    route = patterns.route_for(behavior.pattern, patterns.Region.of(behavior.area, cfg.home), behavior.altitude,
                               camera, mission.frame_rate_hz, ratio, max_range, start=cfg.home)
    waypoints = route.waypoints
    if behavior.terrain.enabled:  # each piece of a long leg gets its own height over the terrain
        waypoints = patterns.densify(waypoints, behavior.terrain.leg, start=cfg.home)
    replan = GapReplanner(behavior, cfg.home, cfg.seed) if behavior.pattern.then == "replan" else None
    return Pilot(cfg, behavior, pattern=waypoints, pattern_speed=route.speed, replan=replan)


def build_depth_service(mission: MissionCore) -> DepthService:
    return DepthService(mission.depth, gimbal=mission.gimbal)


HOME_HEIGHT_SPAN = 1000.0  # m: home (the ground the fence's heights count from) within this of the map's z = 0


def map_volume(mission: MissionCore) -> Volume:
    """Where the mission's clouds may reach: the geofence's bounding box with its margin, widened on
    every side by the map server's ``max_range`` (what a drone at the fence's edge can see); heights up
    to the fence's ``alt_max`` above a home within ``HOME_HEIGHT_SPAN`` of z = 0, widened the same way."""
    fence, reach = mission.geofence, mission.map_server.max_range
    if fence.shape == "circle":
        (cx, cy), r = fence.center, fence.radius
        xmin, xmax, ymin, ymax = cx - r, cx + r, cy - r, cy + r
    else:
        xs, ys = zip(*fence.polygon)
        xmin, xmax, ymin, ymax = min(xs), max(xs), min(ys), max(ys)
    out = fence.margin + reach
    return Volume((xmin - out, ymin - out, -HOME_HEIGHT_SPAN - reach),
                  (xmax + out, ymax + out, HOME_HEIGHT_SPAN + fence.alt_max + reach))
