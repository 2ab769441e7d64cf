"""When to turn home: the charge the way home takes, plus a reserve, against the charge left.

The pilot hears the battery as the autopilot reports it (SYS_STATUS battery_remaining, whole
percent, as a fraction) and measures its drain rate over the flight so far; the way home
takes ``horizontal distance / return_speed + height / DESCENT_SPEED`` seconds. The pilot turns
home once ``charge left <= reserve + drain rate x time home``, so it lands with the reserve; a
reserve above the autopilot's own low-battery level (ArduCopter BATT_LOW_MAH, the simulator's
``sim.battery.low_mah``) turns it home before that failsafe would.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

RETURN_PHASE = "return: battery"  # the mission state's phase once the pilot turned home (the link node RTLs)
DESCENT_SPEED = 1.0  # m/s: ArduCopter descends at 1.5 m/s (WPNAV_SPEED_DN), 0.5 m/s below 10 m (LAND_SPEED)
MIN_SPAN_S = 30.0  # the drain rate counts once measured over this much mission time
MIN_DROP = 0.03  # and over this much charge (three of the autopilot's whole percents)


class HomeReturn:
    """Watches the charge; :meth:`due` says when the way home plus the reserve needs all that is left.

    ``home``: (x, y) in the map frame, whose z = 0 is the ground at home. The drain rate is
    measured from the first charge heard to the newest; a charge that goes up (a fresh battery)
    starts the measurement over.
    """

    def __init__(self, home: Sequence[float], reserve: float, return_speed: float) -> None:
        self.home = (float(home[0]), float(home[1]))
        self.reserve = float(reserve)
        self.return_speed = float(return_speed)
        self._first: tuple[float, float] | None = None  # (time, charge) the measurement starts from
        self._last: tuple[float, float] | None = None
        self.why = ""  # set when due: the numbers that said so

    def update(self, time: float, charge: float) -> None:
        """One charge reading (fraction 0..1) at mission ``time``; NaN (unknown) is ignored."""
        if not math.isfinite(charge) or not math.isfinite(time):
            return
        if not 0.0 <= charge <= 1.0:
            raise ValueError(f"battery: expected a fraction in [0, 1], got {charge}")
        if self._first is None or charge > self._last[1] or time < self._last[0]:  # first, swapped, rebooted
            self._first = (time, charge)
        self._last = (time, charge)

    @property
    def drain_rate(self) -> float | None:
        """Charge used per mission second, once measured over MIN_SPAN_S and MIN_DROP; else None."""
        if self._first is None:
            return None
        (t0, c0), (t1, c1) = self._first, self._last
        if t1 - t0 < MIN_SPAN_S or c0 - c1 < MIN_DROP:
            return None
        return (c0 - c1) / (t1 - t0)

    def seconds_home(self, position: Sequence[float]) -> float:
        """Flying back at ``return_speed`` and down to the ground at DESCENT_SPEED."""
        horizontal = math.hypot(position[0] - self.home[0], position[1] - self.home[1])
        height = max(0.0, float(position[2])) if len(position) > 2 else 0.0
        return horizontal / self.return_speed + height / DESCENT_SPEED

    def due(self, position: Sequence[float], time: float, charge: float) -> bool:
        """Read ``charge`` and say whether the pilot must turn home now (``why`` then says why)."""
        self.update(time, charge)
        if self._last is None:
            return False
        left, rate = self._last[1], self.drain_rate
        home_s = self.seconds_home(position)
        needed = self.reserve + (rate or 0.0) * home_s
        if left > needed:
            return False
        rate_text = "not measured yet" if rate is None else f"{100 * rate * 60:.2f} %/min"
        self.why = (f"battery {100 * left:.0f}% <= reserve {100 * self.reserve:.0f}% + "
                    f"{100 * (needed - self.reserve):.1f}% for {home_s:.0f} s home (drain {rate_text})")
        return True
