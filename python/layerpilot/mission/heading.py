"""The camera heading a behavior holds: part of the behavior, because two-view stereo needs it.

The frame picker pairs two frames only when the camera turned at most 15 degrees between
them and moved sideways enough (docs/depth.md). A drone that faces every new waypoint turns
the camera at every decision, and most frames find no partner. A behavior's ``[flight]``
table chooses the rule (``heading``):

- ``target``: face the new waypoint (the paper's drones; the camera turns at every decision),
- ``side``: look 90 degrees to the hop, on the side of the area's centre: the motion is along
  the image rows, the best case for two-view stereo (the orbit's motion); the camera turns once
  per decision, then holds,
- ``fixed``: hold ``yaw_deg`` all mission long, a survey direction; the camera never turns, so
  with the camera pitched down every horizontal move keeps the epipole above the image and
  consecutive frames pair (``yaw_deg = 0``, east, is the take-off heading: "hold heading"); but
  a hop diagonal to the camera pairs frames the matcher cannot use (measured: no points),
- ``center``: face the centre of the area of interest, as the orbit does (the camera turns
  slowly far from the centre, fast near it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from layerpilot.decide.behavior import Area, Behavior, Flight
from layerpilot.layers.view_gain import heading_yaw


def area_center(area: Area, home: Sequence[float]) -> tuple[float, float]:
    """The area's centre: the circle's centre (default: home) or the polygon's vertex mean."""
    if area.shape == "polygon":
        p = np.asarray(area.polygon, np.float64)
        return float(p[:, 0].mean()), float(p[:, 1].mean())
    c = area.center if area.center is not None else home
    return float(c[0]), float(c[1])


class HeadingPolicy:
    """The yaw (ENU rad) each command carries under a behavior's heading rule (``heading_yaw``)."""

    def __init__(self, behavior: Behavior, home: Sequence[float]) -> None:
        self.flight: Flight = behavior.flight
        self.center = area_center(behavior.area, home)

    @property
    def fixed_yaw(self) -> float:
        """The heading of a ``fixed`` rule (ENU rad)."""
        return math.radians(self.flight.yaw_deg)

    def yaw(self, position: Sequence[float], waypoint: Sequence[float]) -> float:
        """Heading to hold on the way to ``waypoint`` from ``position`` (map frame)."""
        if self.flight.heading == "center" and math.dist(self.center, waypoint[:2]) < 1e-6:
            return self.yaw_of("target", position, waypoint)  # at the centre: keep looking along the way in
        return self.yaw_of(self.flight.heading, position, waypoint)

    def yaw_of(self, rule: str, position: Sequence[float], waypoint: Sequence[float]) -> float:
        return float(heading_yaw(rule, position, waypoint[0], waypoint[1], self.fixed_yaw, self.center))
