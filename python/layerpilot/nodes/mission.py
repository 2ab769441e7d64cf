"""A mission file: which vehicles fly, and one table per node role, all validated on load.

Every table is checked by its node's own dataclass, so ``layerpilot up`` refuses a bad
file before anything starts and the error names the key (e.g. ``decide.arrival_radius``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from layerpilot.config import ConfigError, check_range, from_dict, load_toml, shipped_config

MISSION_DIR = shipped_config("missions")


@dataclass(frozen=True)
class Mission:
    description: str = ""
    vehicles: list[str] = field(default_factory=lambda: ["uav1"])
    speed: float = 1.0  # simulator pace (x real time)
    camera_only: bool = False  # the vehicle is a real autopilot (SITL) at [link.link].url; sim only renders
    mavlink_port: int = 5760  # vehicle i's simulator serves MAVLink on tcp:127.0.0.1:<mavlink_port + 10 i>
    bus: dict[str, Any] = field(default_factory=dict)
    map_server: dict[str, Any] = field(default_factory=dict)
    depth: dict[str, Any] = field(default_factory=dict)
    decide: dict[str, Any] = field(default_factory=dict)
    link: dict[str, Any] = field(default_factory=dict)
    sim: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from layerpilot.bus.keys import check_vehicle

        check_range("speed", self.speed, 0.01, 100.0)
        check_range("mavlink_port", self.mavlink_port, 1024, 65000)
        if not self.vehicles or len(set(self.vehicles)) != len(self.vehicles):
            raise ConfigError(f"vehicles: need one or more distinct names, got {self.vehicles}")
        for v in self.vehicles:
            check_vehicle(v)

    def mavlink_url(self, vehicle: str) -> str:
        return f"tcp:127.0.0.1:{self.mavlink_port + 10 * self.vehicles.index(vehicle)}"


def resolve(name_or_path: str | Path | None) -> Path:
    """``None`` -> the default mission; a bare name -> config/missions/<name>.toml; else a path."""
    if name_or_path is None:
        return MISSION_DIR / "default.toml"
    p = Path(name_or_path)
    if p.suffix != ".toml" and not p.exists():
        p = MISSION_DIR / f"{p}.toml"
    return p


def load_mission(name_or_path: str | Path | None = None) -> tuple[Mission, dict[str, Any]]:
    """The validated mission and its raw tables (what the nodes read)."""
    path = resolve(name_or_path)
    tables = load_toml(path)
    try:
        mission = from_dict(Mission, tables, "mission")
        validate_tables(tables)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    return mission, tables


def validate_tables(tables: dict[str, Any]) -> None:
    from layerpilot.bus.session import BusConfig
    from layerpilot.decide.behavior import load_behavior
    from layerpilot.nodes.decide import DecideConfig
    from layerpilot.nodes.depth import DepthNodeConfig
    from layerpilot.nodes.link import LinkNodeConfig
    from layerpilot.nodes.map_server import MapServerConfig
    from layerpilot.sim.simulator import SimConfig

    for name, cls in (("bus", BusConfig), ("map_server", MapServerConfig), ("depth", DepthNodeConfig),
                      ("decide", DecideConfig), ("link", LinkNodeConfig), ("sim", SimConfig)):
        from_dict(cls, tables.get(name, {}), name)
    load_behavior(from_dict(DecideConfig, tables.get("decide", {}), "decide").behavior)
