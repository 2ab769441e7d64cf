"""The mission clock: one clock over all of a survey's flights.

Every stamp of a mission (poses, camera frames, so clouds, map insertion times, layer sets,
decisions, the saved survey) is on the vehicle's clock: the autopilot's time_boot_ms, which the
simulator's clock equals. An autopilot that is switched off for a battery swap starts that
clock at 0 again, so a resumed flight (``up --resume``) stamps ``start + vehicle time``, with
``start`` the newest mission time its survey saved: cells seen in an earlier flight are as old
as they are, and ``after_time`` schedule phases count on. The stamps are made on this clock
where they are made (the link node's poses, the simulator node's frames); every consumer reads
them as they come. An autopilot that reboots in flight (``link.on_reboot = "pause"``) also counts
from 0 again: the link node moves its clock on by the uptime before the reboot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class MissionClock:
    """Mission time = ``start`` + the vehicle's clock (s); ``start`` is 0 for a mission's first flight."""

    start: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start) and self.start >= 0.0):
            raise ValueError(f"mission clock start: expected finite seconds >= 0, got {self.start}")

    def __call__(self, vehicle_time: float) -> float:
        return self.start + vehicle_time

    def after_reboot(self, uptime: float) -> "MissionClock":
        """The clock once the vehicle's clock restarted at 0 after ``uptime`` s (a reboot in flight): on
        from where it was, so that stamps never go back (the map keeps the newest as a cell's last_seen)."""
        return MissionClock(self.start + uptime)
