"""One typed mission: a TOML file parsed once into sections that every command reads.

The edge of the system: besides the core's sections (``Mission.core``: map server, depth, decide, the
drone's camera) it says how the bus, the link and the simulator are set up.

``layerpilot up``, every node, ``demo`` and ``study`` take a mission file (a path or a name
in config/missions/); command-line flags override fields of it. Unknown keys and
out-of-range values are errors that name the key (``map_server.resolution``), or, when a
flag set the value, the flag (``--world-size must be in [20.0, 5000.0], got -1.0``).
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from layerpilot.bus.keys import check_vehicle
from layerpilot.bus.session import BusConfig
from layerpilot.config import ConfigError, RangeError, check_range, from_dict, load_toml, shipped_config
from layerpilot.link.config import LinkConfig
from layerpilot.link.geofence import Geofence
from layerpilot.mission.camera_track import CameraSettings
from layerpilot.mission.core import MissionCore
from layerpilot.mission.depth_service import DepthServiceConfig
from layerpilot.mission.map_service import MapServiceConfig
from layerpilot.mission.pilot import PilotConfig
from layerpilot.ros2.topics import Ros2Config
from layerpilot.sim.simulator import SimConfig

MISSION_DIR = shipped_config("missions")


@dataclass(frozen=True)
class LinkSettings:
    """The ``[link]`` table: the flight link's settings (``[link.link]``) plus the link node's own."""

    link: LinkConfig = field(default_factory=LinkConfig)
    takeoff_altitude: float = 30.0  # m above home
    pose_rate: float = 10.0  # Hz
    geofence_margin: float = 20.0  # m the geofence reaches beyond the behavior's area of interest
    end_action: str = "rtl"  # what the link node commands when the mission ends: rtl, land or loiter
    end_timeout: float = 10.0  # s the link node waits for the end action's COMMAND_ACK and mode change
    on_reboot: str = "end"  # the autopilot rebooted: "end" the flying, or "pause" until a pilot hands GUIDED back
    separation: float = 10.0  # m: a fleet's waypoint nearer another drone (its position or target) is refused; 0 off
    separation_stale_s: float = 5.0  # s without news of a drone: it no longer counts

    def __post_init__(self) -> None:
        check_range("link.takeoff_altitude", self.takeoff_altitude, 1.0, 500.0)
        check_range("link.pose_rate", self.pose_rate, 0.1, 100.0)
        check_range("link.geofence_margin", self.geofence_margin, 0.0, 10_000.0)
        if self.end_action not in ("rtl", "land", "loiter"):
            raise ConfigError(f"link.end_action: expected 'rtl', 'land' or 'loiter', got {self.end_action!r}")
        check_range("link.end_timeout", self.end_timeout, 1.0, 12.0)  # inside `up`'s 15 s stop grace
        if self.on_reboot not in ("end", "pause"):
            raise ConfigError(f"link.on_reboot: expected 'end' or 'pause', got {self.on_reboot!r}")
        check_range("link.separation", self.separation, 0.0, 10_000.0)
        check_range("link.separation_stale_s", self.separation_stale_s, 0.1, 3600.0)


@dataclass(frozen=True)
class EvaluationSettings:
    """The ``[evaluation]`` table: how ``demo`` and ``study`` fly the mission in lock-step and score it."""

    duration: float = 600.0  # mission seconds
    step_s: float = 0.05  # simulator step of the lock-step loop
    seeds: int = 3  # decision seeds per MCDM behavior in a study
    behaviors: list[str] = field(default_factory=lambda: ["balanced", "exploration", "time", "distance",
                                                          "lawnmower", "orbit"])  # a study's behaviors
    out: str = "runs"  # parent directory of run directories
    overlap: bool = True  # run a frame's stereo and the truth beside the simulator (results identical to False)

    def __post_init__(self) -> None:
        check_range("evaluation.duration", self.duration, 1.0, 36_000.0)
        check_range("evaluation.step_s", self.step_s, 0.005, 0.5)
        check_range("evaluation.seeds", self.seeds, 1, 100)
        if not self.behaviors:
            raise ConfigError("evaluation.behaviors: give at least one behavior")


@dataclass(frozen=True)
class Mission:
    """Which vehicles fly, and one typed section per part of the system."""

    description: str = ""
    vehicles: list[str] = field(default_factory=lambda: ["uav1"])
    speed: float = 1.0  # simulator pace in live missions (x real time)
    camera_only: bool = False  # the vehicle is a real autopilot (SITL) at link.link.url; sim only renders
    mavlink_port: int = 5760  # vehicle i's simulator serves MAVLink on tcp:127.0.0.1:<mavlink_port + 10 i>
    bus: BusConfig = field(default_factory=BusConfig)
    map_server: MapServiceConfig = field(default_factory=MapServiceConfig)
    depth: DepthServiceConfig = field(default_factory=DepthServiceConfig)
    decide: PilotConfig = field(default_factory=PilotConfig)
    link: LinkSettings = field(default_factory=LinkSettings)
    sim: SimConfig = field(default_factory=SimConfig)
    camera: CameraSettings = field(default_factory=CameraSettings)
    evaluation: EvaluationSettings = field(default_factory=EvaluationSettings)
    ros2: Ros2Config = field(default_factory=Ros2Config)

    def __post_init__(self) -> None:
        check_range("speed", self.speed, 0.01, 100.0)
        check_range("mavlink_port", self.mavlink_port, 1024, 65000)
        if not self.vehicles or len(set(self.vehicles)) != len(self.vehicles):
            raise ConfigError(f"vehicles: need one or more distinct names, got {self.vehicles}")
        for v in self.vehicles:
            check_vehicle(v)

    @property
    def core(self) -> MissionCore:
        """What the mission core needs of this mission (the pipeline's settings); ``depth.pairs = "auto"``
        becomes ``survey`` for a photo folder, else ``video``."""
        depth = self.depth if self.depth.pairs != "auto" else dataclasses.replace(
            self.depth, pairs="survey" if self.camera.plays_photos else "video")
        return MissionCore(tuple(self.vehicles), self.map_server, depth, self.decide, self.simulator.camera,
                           self.sim.frame_rate_hz, self.camera.gimbal, geofence_for(self))

    @property
    def simulator(self) -> SimConfig:
        """The ``[sim]`` table as flown: the camera at the decide behavior's mount (``camera_pitch_deg``) when
        the behavior states one (a nadir survey), else at ``sim.camera.pitch_deg``."""
        pitch = self.decide.flown_behavior().camera_pitch_deg
        if pitch is None:
            return self.sim
        return dataclasses.replace(self.sim, camera=dataclasses.replace(self.sim.camera, pitch_deg=pitch))

    def mavlink_url(self, vehicle: str) -> str:
        return f"tcp:127.0.0.1:{self.mavlink_port + 10 * self.vehicles.index(vehicle)}"


def geofence_for(mission: Mission) -> Geofence:
    """The mission's geofence, which the link enforces whoever sends a waypoint (the live link node,
    `layerpilot link` actions and the lock-step evaluator all take it from here).

    Area: the decide behavior's area of interest, a circle
    around ``area.center`` (else ``decide.home``) or its polygon, widened by
    ``link.geofence_margin``; heights above home: ``link.link.alt_min_m`` .. ``alt_max_m``.
    """
    area = mission.decide.flown_behavior().area
    limits = dict(margin=mission.link.geofence_margin, alt_min=mission.link.link.alt_min_m,
                  alt_max=mission.link.link.alt_max_m)
    if area.shape == "polygon":
        return Geofence.polygon_of(area.polygon, **limits)
    return Geofence.circle(area.center if area.center is not None else mission.decide.home, area.radius, **limits)


@dataclass(frozen=True)
class Override:
    """A command-line flag that sets one field: ``Override("--world-size", "sim.world.size", -1.0)``."""

    flag: str
    key: str  # dotted path into the mission's tables
    value: Any


def resolve(name_or_path: str | Path | None) -> Path:
    """``None`` -> the default mission; a bare name -> config/missions/<name>.toml; else a path."""
    if name_or_path is None:
        return MISSION_DIR / "default.toml"
    p = Path(name_or_path)
    if p.suffix != ".toml" and not p.exists():
        p = MISSION_DIR / f"{p}.toml"
    return p


def load_mission(name_or_path: str | Path | None = None, overrides: list[Override] = ()) -> Mission:
    """Parse and validate a mission file, then apply flag overrides (errors name the flag)."""
    path = resolve(name_or_path)
    tables = load_toml(path)
    try:
        mission = from_dict(Mission, tables, "mission")
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    return apply_overrides(mission, tables, overrides) if overrides else mission


def apply_overrides(mission: Mission, tables: dict[str, Any], overrides: list[Override]) -> Mission:
    """The mission with each flag's value set; a bad value is reported under the flag's name."""
    merged = copy.deepcopy(tables)
    for o in overrides:
        one = copy.deepcopy(tables)
        _set(one, o.key, o.value)
        try:
            from_dict(Mission, one, "mission")
        except RangeError as exc:
            raise ConfigError(f"{o.flag} {exc.requirement()}, got {o.value}") from None
        except ConfigError as exc:
            reason = str(exc).split(": ", 1)[-1] if ": " in str(exc) else str(exc)
            raise ConfigError(f"{o.flag} {o.value!r}: {reason}") from None
        _set(merged, o.key, o.value)
    mission = from_dict(Mission, merged, "mission")
    mount = mission.decide.flown_behavior().camera_pitch_deg
    for o in overrides:
        if o.key == "sim.camera.pitch_deg" and mount is not None and mount != o.value:
            raise ConfigError(f"{o.flag} {o.value}: behavior {mission.decide.behavior!r} flies its own camera mount "
                              f"(camera_pitch_deg = {mount:g}); set it in a copy of the behavior file")
    return mission


def _set(tables: dict[str, Any], key: str, value: Any) -> None:
    *parents, leaf = key.split(".")
    node = tables
    for name in parents:
        node = node.setdefault(name, {})
    node[leaf] = value


def to_tables(mission: Mission) -> dict[str, Any]:
    """The mission as plain nested tables, the simulator's camera as flown (``Mission.simulator``)."""
    return dataclasses.asdict(dataclasses.replace(mission, sim=mission.simulator))


def to_settings(mission: Mission) -> dict[str, Any]:
    """The mission as one flat table of dotted keys (``sim.world.seed``), as run reports show it."""
    flat: dict[str, Any] = {}

    def walk(table: dict[str, Any], prefix: str) -> None:
        for key, value in table.items():
            if isinstance(value, dict) and value and key not in ("transport", "access_control"):
                walk(value, f"{prefix}{key}.")
            else:
                flat[prefix + key] = value

    walk(to_tables(mission), "")
    return flat
