"""Keeping a fleet apart in the link: a waypoint too near another drone, where it is or where it is going,
is refused like one outside the geofence, whatever chose it.

The link hears the other drones' positions and targets (the link node from the bus, the lock-step
evaluator from its fleet) and forgets a drone it has not heard from for ``stale_after`` seconds: a
drone that dropped out no longer blocks its part of the area.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence

from layerpilot.config import check_range
from layerpilot.link.geofence import OutsideGeofence


class Separation:
    """The other drones' newest positions and targets (map frame, x y) and the distance to keep from them."""

    def __init__(self, min_distance: float, stale_after: float = 5.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        check_range("separation", min_distance, 0.0, 10_000.0)
        check_range("separation_stale_s", stale_after, 0.1, 3600.0)
        self.min_distance, self.stale_after, self.clock = float(min_distance), float(stale_after), clock
        self._others: dict[str, tuple[float, tuple[float, float], tuple[float, float] | None]] = {}
        self._lock = threading.Lock()

    def heard(self, vehicle: str, position: Sequence[float] | None = None,
              target: Sequence[float] | None = None) -> None:
        """News of ``vehicle``: its position and/or its target (None keeps what was heard before)."""
        with self._lock:
            _, old_position, old_target = self._others.get(vehicle, (0.0, None, None))
            position = old_position if position is None else (float(position[0]), float(position[1]))
            target = old_target if target is None else (float(target[0]), float(target[1]))
            self._others[vehicle] = (self.clock(), position, target)

    def check(self, x: float, y: float) -> None:
        """Nothing if (x, y) keeps ``min_distance`` from every drone heard lately, else
        :class:`OutsideGeofence` of kind ``separation`` naming the drone and how near."""
        if self.min_distance <= 0.0:
            return
        now = self.clock()
        with self._lock:
            others = [(v, p, t) for v, (heard, p, t) in self._others.items() if now - heard <= self.stale_after]
        for vehicle, position, target in others:
            for what, point in (("position", position), ("target", target)):
                if point is not None and (d := math.hypot(x - point[0], y - point[1])) < self.min_distance:
                    raise OutsideGeofence("separation", f"waypoint ({x:.1f}, {y:.1f}) is {d:.1f} m from {vehicle}'s "
                                                        f"{what}, under the {self.min_distance:g} m separation; "
                                                        f"not sent")
