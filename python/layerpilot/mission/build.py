"""Step objects from a mission: the one place where the live nodes and the evaluator get them."""

from __future__ import annotations

import dataclasses

from layerpilot.link.geofence import Geofence
from layerpilot.mission import flight
from layerpilot.mission.heading import HeadingPolicy
from layerpilot.mission.config import Mission
from layerpilot.mission.depth_service import DepthService, stereo_preset
from layerpilot.mission.map_service import Volume
from layerpilot.mission.pilot import Pilot, load_pilot_behavior


def build_pilot(mission: Mission) -> Pilot:
    """The mission's pilot: the decision maker, or a pattern flown at the survey speed its camera allows."""
    cfg = mission.decide
    behavior = load_pilot_behavior(cfg.behavior)
    if cfg.pattern is None:  # stereo-aware flight: the behavior's heading, survey speed and footprint hops
        camera, max_range = mission.sim.camera, mission.depth.max_depth
        behavior = flight.flight_behavior(behavior, camera, max_range)
        ratio = stereo_preset(camera.width).pick.target_baseline_ratio
        speed = flight.cruise_speed(behavior, camera, mission.sim.frame_rate_hz, ratio, cfg.speed)
        view = (flight.camera_view(behavior, HeadingPolicy(behavior, cfg.home), camera, max_range)
                if "view_gain" in behavior.layer_names else None)
        return Pilot(dataclasses.replace(cfg, speed=speed), behavior, seed=cfg.seed, view=view)
    from layerpilot.mission import patterns

    camera, altitude = mission.sim.camera, behavior.altitude
    centre, radius = behavior.area.center or cfg.home, behavior.area.radius
    if cfg.pattern == "lawnmower":
        waypoints = patterns.lawnmower(centre, radius, altitude, camera, altitude)
        # straight legs at top speed put frames too far apart for stereo: fly at the survey speed
        ratio = stereo_preset(camera.width).pick.target_baseline_ratio
        speed = patterns.survey_speed(camera, altitude, mission.sim.frame_rate_hz, ratio)
    else:
        waypoints, speed = patterns.orbit(centre, radius, altitude), cfg.speed
    return Pilot(cfg, behavior, pattern=waypoints, pattern_speed=speed)


def build_depth_service(mission: Mission) -> DepthService:
    return DepthService(mission.depth, gimbal=mission.camera.gimbal)


def geofence_for(mission: Mission) -> Geofence:
    """The mission's geofence, which the link enforces whoever sends a waypoint (the live link node,
    `layerpilot link` actions and the lock-step evaluator all take it from here).

    Area: the decide behavior's area of interest (a pattern's: the balanced preset's), a circle
    around ``area.center`` (else ``decide.home``) or its polygon, widened by
    ``link.geofence_margin``; heights above home: ``link.link.alt_min_m`` .. ``alt_max_m``.
    """
    area = load_pilot_behavior(mission.decide.behavior).area
    limits = dict(margin=mission.link.geofence_margin, alt_min=mission.link.link.alt_min_m,
                  alt_max=mission.link.link.alt_max_m)
    if area.shape == "polygon":
        return Geofence.polygon_of(area.polygon, **limits)
    return Geofence.circle(area.center if area.center is not None else mission.decide.home, area.radius, **limits)


HOME_HEIGHT_SPAN = 1000.0  # m: home (the ground the fence's heights count from) within this of the map's z = 0


def map_volume(mission: Mission) -> Volume:
    """Where the mission's clouds may reach: the geofence's bounding box with its margin, widened on
    every side by the map server's ``max_range`` (what a drone at the fence's edge can see); heights up
    to the fence's ``alt_max`` above a home within ``HOME_HEIGHT_SPAN`` of z = 0, widened the same way."""
    fence, reach = geofence_for(mission), mission.map_server.max_range
    if fence.shape == "circle":
        (cx, cy), r = fence.center, fence.radius
        xmin, xmax, ymin, ymax = cx - r, cx + r, cy - r, cy + r
    else:
        xs, ys = zip(*fence.polygon)
        xmin, xmax, ymin, ymax = min(xs), max(xs), min(ys), max(ys)
    out = fence.margin + reach
    return Volume((xmin - out, ymin - out, -HOME_HEIGHT_SPAN - reach),
                  (xmax + out, ymax + out, HOME_HEIGHT_SPAN + fence.alt_max + reach))
