"""The simulated flight battery: charge drawn while the motors turn, reported as ArduCopter reports it.

A pack of ``capacity_mah`` drains at ``flight_current_a`` while armed and ``idle_current_a``
otherwise; the voltage falls linearly from ``full_v`` to ``empty_v`` with the charge used.
When the charge left reaches ``low_mah`` (ArduCopter's BATT_LOW_MAH) the autopilot's own
battery failsafe triggers (the endpoint switches to RTL, as BATT_FS_LOW_ACT = 2 does): a
mission that wants to land with a reserve must turn home before that.
"""

from __future__ import annotations

from dataclasses import dataclass

from layerpilot.config import check_range

MAH_PER_AMP_SECOND = 1.0 / 3.6  # 1 A for 1 s is 1/3.6 mAh


@dataclass(frozen=True)
class BatteryConfig:
    """The ``[sim.battery]`` table (ArduCopter's BATT_CAPACITY and BATT_LOW_MAH where they exist)."""

    capacity_mah: float = 5000.0    # BATT_CAPACITY
    flight_current_a: float = 15.0  # armed: 5000 mAh last 20 min of flight
    idle_current_a: float = 0.5     # disarmed: the autopilot and the companion computer
    full_v: float = 16.8            # a 4S pack, full
    empty_v: float = 13.2           # and empty
    low_mah: float = 750.0          # BATT_LOW_MAH: the autopilot's failsafe RTLs at this much left; 0 = off

    def __post_init__(self) -> None:
        check_range("sim.battery.capacity_mah", self.capacity_mah, 1.0, 1e6)
        check_range("sim.battery.flight_current_a", self.flight_current_a, 0.0, 1000.0)
        check_range("sim.battery.idle_current_a", self.idle_current_a, 0.0, 1000.0)
        check_range("sim.battery.empty_v", self.empty_v, 0.0, 100.0)
        check_range("sim.battery.full_v", self.full_v, self.empty_v, 100.0)
        check_range("sim.battery.low_mah", self.low_mah, 0.0, self.capacity_mah)


class Battery:
    """Charge used so far; :meth:`drain` every step, :meth:`swap` for a fresh pack."""

    def __init__(self, cfg: BatteryConfig) -> None:
        self.cfg = cfg
        self.consumed_mah = 0.0
        self.current_a = cfg.idle_current_a

    def drain(self, dt: float, armed: bool) -> None:
        self.current_a = self.cfg.flight_current_a if armed else self.cfg.idle_current_a
        self.consumed_mah = min(self.cfg.capacity_mah, self.consumed_mah + self.current_a * dt * MAH_PER_AMP_SECOND)

    def swap(self) -> None:
        self.consumed_mah = 0.0

    @property
    def remaining(self) -> float:
        """Charge left as a fraction of the capacity, 0..1."""
        return max(0.0, 1.0 - self.consumed_mah / self.cfg.capacity_mah)

    @property
    def voltage(self) -> float:
        return self.cfg.empty_v + self.remaining * (self.cfg.full_v - self.cfg.empty_v)

    @property
    def low(self) -> bool:
        """The autopilot's low-battery failsafe condition (BATT_LOW_MAH)."""
        return self.cfg.low_mah > 0.0 and self.cfg.capacity_mah - self.consumed_mah <= self.cfg.low_mah
