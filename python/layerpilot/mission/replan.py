"""A scripted pattern's follow-up (``pattern.then = "replan"``): after each pass, the next flight over the gaps.

What a survey pilot does after a survey: look at the map, then fly over what it missed or what has
gone stale (`layerpilot plan next`, ``decide.next_flight``). Here the pilot does it on the live map
the moment a pass ends, with the behavior's weights, and flies the plan as the next pass.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from layerpilot.decide.behavior import Behavior
from layerpilot.decide.next_flight import plan_next_flight
from layerpilot.map.columns import ColumnLayers
from layerpilot.mission.heading import HeadingPolicy


class GapReplanner:
    """(columns, position, time) -> (M, 4) waypoints x, y, z, yaw over the map's unobserved and stale cells."""

    def __init__(self, behavior: Behavior, home: Sequence[float], seed: int | None = None) -> None:
        self.behavior, self.home, self.seed = behavior, (float(home[0]), float(home[1])), seed
        self.heading = HeadingPolicy(behavior, home)
        self.plans = 0

    def __call__(self, columns: ColumnLayers, position: Sequence[float], time: float) -> np.ndarray:
        seed = None if self.seed is None else self.seed + self.plans  # a fresh draw per plan, reproducible
        self.plans += 1
        plan = plan_next_flight(columns, self.behavior, home=self.home, start=position, now=time,
                                stale_after=self.behavior.pattern.stale_after, seed=seed)
        rows, at = [], position
        for wp in plan.waypoints:
            rows.append((*wp, self.heading.yaw(at, wp)))
            at = wp
        return np.asarray(rows, np.float64).reshape(-1, 4)
