"""How the simulated autopilot behaves (:class:`EndpointConfig`) and where its map frame lies on the Earth."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from layerpilot.config import check_range
from layerpilot.geodesy import LocalFrame
from layerpilot.link import modes
from layerpilot.sim.battery import BatteryConfig
from layerpilot.sim.sensors import SensorProfile

DEFAULT_URL = "tcp:127.0.0.1:5760"
SITL_DATUM = LocalFrame(47.397742, 8.545594, 488.0)  # the PX4/ArduPilot SITL default field near Zurich


@dataclass(frozen=True)
class EndpointConfig:
    """How the simulated autopilot behaves; times are mission seconds."""

    flavour: Literal["ardupilot", "px4"] = "ardupilot"
    origin: LocalFrame = SITL_DATUM   # where the map frame lies on the Earth (geodesy.LocalFrame)
    system_id: int = 1
    component_id: int = 1
    prearm_delay_s: float = 2.0        # GPS fix at half of it, pre-arm checks healthy after it
    auto_disarm_s: float = 10.0        # ArduCopter DISARM_DELAY / PX4 COM_DISARM_PRFLT
    rtl_alt_m: float = 15.0            # ArduCopter RTL_ALT (above home)
    land_speed_m_s: float = 0.5        # ArduCopter LAND_SPEED, below land_slow_below_m
    land_slow_below_m: float = 10.0
    offboard_loss_s: float = 1.0       # PX4 COM_OF_LOSS_T
    offboard_min_rate_hz: float = 2.0  # PX4 wants a setpoint stream faster than this before OFFBOARD
    battery: BatteryConfig = field(default_factory=BatteryConfig)  # SYS_STATUS, BATTERY_STATUS, failsafe
    sensors: SensorProfile = field(default_factory=SensorProfile)  # the EKF's errors (default: none)
    seed: int = 0                      # of the sensor errors' generator

    def __post_init__(self) -> None:
        if self.flavour not in (modes.ARDUPILOT, modes.PX4):
            raise ValueError(f"flavour: expected 'ardupilot' or 'px4', got {self.flavour!r}")
        check_range("system_id", self.system_id, 1, 255)
        check_range("component_id", self.component_id, 1, 255)
        for name in ("prearm_delay_s", "auto_disarm_s", "rtl_alt_m", "land_slow_below_m"):
            check_range(name, getattr(self, name), 0.0, None)
        for name in ("land_speed_m_s", "offboard_loss_s", "offboard_min_rate_hz"):
            check_range(name, getattr(self, name), 1e-6, None)
