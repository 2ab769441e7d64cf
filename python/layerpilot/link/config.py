"""Flight link settings: where the autopilot is, who we are, timeouts and limits.

Times are wall-clock seconds (they guard a real radio link); lengths are metres
in the map frame (ENU). Loaded from the ``[link]`` table of a mission file with
:func:`layerpilot.config.from_dict`, so a wrong key or value names itself. Where the
vehicle may go is not a setting here: the geofence (:mod:`layerpilot.link.geofence`)
is built from the mission and given to the link.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from layerpilot.config import ConfigError, check_range
from layerpilot.link.connection import parse_url


@dataclass(frozen=True)
class LinkConfig:
    url: str = "tcp:127.0.0.1:5760"
    baud: int = 57600
    source_system: int = 1            # same system as the autopilot, like a companion computer
    source_component: int = 191       # MAV_COMP_ID_ONBOARD_COMPUTER
    target_system: int = 0            # 0: the first ArduPilot/PX4 autopilot heard
    target_component: int = 0         # 0: the component that sent that HEARTBEAT
    connect_timeout_s: float = 30.0
    heartbeat_timeout_s: float = 3.0  # no autopilot HEARTBEAT for this long = link lost
    long_loss_s: float = 20.0         # a loss longer than this triggers long_loss_action when the link returns
    long_loss_action: Literal["none", "rtl", "land"] = "none"
    ready_timeout_s: float = 120.0     # a cold-started ArduPilot SITL took 41 s to be ready
    command_timeout_s: float = 1.5    # per COMMAND_LONG attempt
    command_retries: int = 3
    arm_timeout_s: float = 10.0
    mode_timeout_s: float = 5.0
    setpoint_period_s: float = 0.2    # 5 Hz: above PX4's 2 Hz minimum, far inside both autopilots' timeouts
    offboard_prestream_s: float = 1.0
    arrival_tolerance_m: float = 1.0
    arrival_hold_s: float = 1.0
    telemetry_rate_hz: float = 10.0
    alt_min_m: float = 2.0            # waypoint height above home (the mission's geofence takes it)
    alt_max_m: float = 120.0

    def __post_init__(self) -> None:
        check_range("source_system", self.source_system, 1, 255)
        check_range("source_component", self.source_component, 1, 255)
        check_range("target_system", self.target_system, 0, 255)
        check_range("target_component", self.target_component, 0, 255)
        for name in ("connect_timeout_s", "heartbeat_timeout_s", "long_loss_s", "ready_timeout_s",
                     "command_timeout_s", "arm_timeout_s", "mode_timeout_s", "setpoint_period_s",
                     "arrival_tolerance_m", "telemetry_rate_hz"):
            check_range(name, getattr(self, name), 1e-6, None)
        check_range("setpoint_period_s", self.setpoint_period_s, None, 0.4)  # PX4 needs > 2 Hz
        check_range("command_retries", self.command_retries, 0, 100)
        check_range("offboard_prestream_s", self.offboard_prestream_s, 0.0, None)
        check_range("arrival_hold_s", self.arrival_hold_s, 0.0, None)
        if self.long_loss_action not in ("none", "rtl", "land"):
            raise ConfigError(f"long_loss_action: expected 'none', 'rtl' or 'land', got {self.long_loss_action!r}")
        try:
            parse_url(self.url, self.baud)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        if not self.alt_min_m < self.alt_max_m:
            raise ConfigError(f"alt_min_m: must be below alt_max_m ({self.alt_min_m} >= {self.alt_max_m})")
