"""Behaviors: what the drone prefers, as a validated TOML file (presets in config/behaviors/).

Every key is documented in docs/decide.md. Errors name the key with its path, e.g.
``balanced.toml: behavior.area: radius = -5.0 must be > 0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from layerpilot.config import ConfigError, from_dict, load_toml, shipped_config
from layerpilot.layers.registry import LayerOptions, layer_names, load_plugins

PRESET_DIR = shipped_config("behaviors")


def _positive(name: str, value: float) -> None:
    if not value > 0:
        raise ValueError(f"{name} = {value} must be > 0")


def _check_weights(weights: dict[str, float], key: str) -> None:
    for name, w in weights.items():
        if not w >= 0:
            raise ValueError(f"{key}.{name} = {w} must be >= 0")
    if not any(w > 0 for w in weights.values()):
        raise ValueError(f"{key}: at least one weight must be > 0")


@dataclass(frozen=True)
class Area:
    """Area of interest Z: a circle around the launch point (or ``center``), or a polygon (map frame)."""

    shape: Literal["circle", "polygon"] = "circle"
    radius: float = 100.0
    center: tuple[float, float] | None = None  # None: the launch / operator point
    polygon: list[tuple[float, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        _positive("radius", self.radius)
        if self.shape == "polygon" and len(self.polygon) < 3:
            raise ValueError(f"polygon: a polygon area needs at least 3 (x, y) vertices, got {len(self.polygon)}")
        if self.shape == "circle" and self.polygon:
            raise ValueError("polygon: given but shape = 'circle'; set shape = 'polygon'")


@dataclass(frozen=True)
class SchedulePhase:
    """Weights that take over once mission time or coverage of the area of interest reaches a value."""

    weights: dict[str, float]
    after_time: float | None = None  # mission seconds
    after_coverage: float | None = None  # fraction of the area of interest observed, 0..1

    def __post_init__(self) -> None:
        if (self.after_time is None) == (self.after_coverage is None):
            raise ValueError("give exactly one of after_time, after_coverage")
        if self.after_time is not None and not self.after_time >= 0:
            raise ValueError(f"after_time = {self.after_time} must be >= 0")
        if self.after_coverage is not None and not 0 <= self.after_coverage <= 1:
            raise ValueError(f"after_coverage = {self.after_coverage} is out of range [0, 1]")
        _check_weights(self.weights, "weights")


@dataclass(frozen=True)
class Retarget:
    """On by default: switch target mid-flight when another cell scores better by ``margin`` (relative).

    The defaults fire a few times in a 300 s mission of every shipped MCDM preset (docs/eval.md,
    "hop defaults"): the margin and interval keep the camera from turning every second.
    """

    enabled: bool = True
    margin: float = 0.3  # new best must exceed the current target's score by 30%
    min_interval: float = 8.0  # seconds between switches (hysteresis in time)
    min_separation: float = 15.0  # metres; a nearer 'better' cell is not worth a switch

    def __post_init__(self) -> None:
        for name in ("margin", "min_interval", "min_separation"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} = {getattr(self, name)} must be >= 0")


@dataclass(frozen=True)
class Terrain:
    """Opt-in: waypoint altitude = highest terrain near the path + clearance, within limits."""

    enabled: bool = False
    clearance: float = 30.0  # metres above the highest column top within the corridor
    corridor: float = 5.0  # metres either side of the straight path to the waypoint
    min_altitude: float = 20.0
    max_altitude: float = 120.0
    leg: float = 25.0  # metres: a scripted pattern's legs are flown in pieces this long, each at its own height

    def __post_init__(self) -> None:
        _positive("leg", self.leg)
        if not self.clearance >= 0:
            raise ValueError(f"clearance = {self.clearance} must be >= 0")
        if not self.corridor >= 0:
            raise ValueError(f"corridor = {self.corridor} must be >= 0")
        if not self.min_altitude <= self.max_altitude:
            raise ValueError(f"min_altitude = {self.min_altitude} must be <= max_altitude = {self.max_altitude}")


@dataclass(frozen=True)
class Flight:
    """How the drone flies between waypoints: camera heading, cruise speed, hop lengths (docs/decide.md).

    ``heading``: ``target`` faces each new waypoint (the camera turns at every decision),
    ``side`` looks 90 deg to the hop towards the area's centre (sideways motion, best for stereo),
    ``fixed`` holds ``yaw_deg`` all mission long (a survey direction; 0 = east, the take-off
    heading, i.e. "hold heading"), ``center`` faces the area's centre as the orbit does.
    ``speed = "survey"`` cruises at the speed that puts consecutive frames one target stereo
    baseline apart (as the lawnmower does); ``"default"`` leaves it to the mission / autopilot.
    ``hops = "footprint"`` derives r_e and r_i from the camera's ground footprint instead of the file;
    a behavior file that sets neither r_e, r_i nor ``hops`` gets ``footprint`` (``behavior_from_dict``),
    one that sets r_e or r_i keeps its metres.
    """

    heading: Literal["target", "side", "fixed", "center"] = "target"
    yaw_deg: float = 0.0
    speed: Literal["default", "survey"] = "default"
    hops: Literal["fixed", "footprint"] = "fixed"

    def __post_init__(self) -> None:
        if not -360.0 <= self.yaw_deg <= 360.0:
            raise ValueError(f"yaw_deg = {self.yaw_deg} is out of range [-360, 360]")


@dataclass(frozen=True)
class Pattern:
    """A scripted flight the pilot flies instead of deciding (docs/decide.md, "Scripted baselines").

    ``survey``: parallel lines, camera along the track (nadir with ``camera_pitch_deg = 90``);
    ``survey-side``: parallel lines, camera 90 deg to the track, always to the same side;
    ``orbit``: once around the area's edge, camera to the centre; ``orbit-rings``: orbits
    inset from the edge until the area is covered. Line and ring spacing is the view's width
    across the track times (1 - ``side_overlap``); the speed puts frames (1 - ``front_overlap``)
    x the view's length along the track apart, or one stereo baseline apart when it is not set;
    ``speed`` (m/s) overrides the rule, 0 leaving it to the autopilot.
    ``then``: after the last waypoint fly the pattern again (``repeat``, a patrol) or plan the next
    flight over the map's gaps with the behavior's weights (``replan``, as `layerpilot plan next`).
    """

    kind: Literal["none", "survey", "survey-side", "orbit", "orbit-rings"] = "none"
    side_overlap: float = 0.3
    front_overlap: float | None = None  # None: consecutive frames one target stereo baseline apart
    speed: float | None = None  # m/s instead of the overlap rule; 0: the autopilot's default speed
    heading_deg: float | None = None  # line direction (ENU deg, 0 = east); None: across the area's narrowest width
    placement: Literal["edges", "centred"] = "edges"  # lines: views on the area's edges, or exactly the spacing
    #   apart and centred on the area (the paper's lawnmower)
    then: Literal["repeat", "replan"] = "repeat"
    step: float = 10.0  # m between waypoints on an orbit
    stale_after: float = 150.0  # s: replan treats a cell seen this long ago as a gap

    def __post_init__(self) -> None:
        if not 0.0 <= self.side_overlap < 1.0:
            raise ValueError(f"side_overlap = {self.side_overlap} is out of range [0, 1)")
        if self.front_overlap is not None and not 0.0 <= self.front_overlap < 1.0:
            raise ValueError(f"front_overlap = {self.front_overlap} is out of range [0, 1)")
        if self.heading_deg is not None and not -360.0 <= self.heading_deg <= 360.0:
            raise ValueError(f"heading_deg = {self.heading_deg} is out of range [-360, 360]")
        _positive("step", self.step)
        _positive("stale_after", self.stale_after)
        if self.speed is not None and not 0.0 <= self.speed <= 100.0:
            raise ValueError(f"speed = {self.speed} is out of range [0, 100]")
        if self.kind == "none" and self.then != "repeat":
            raise ValueError("then: only a pattern (kind) has a pass to follow up")


@dataclass(frozen=True)
class Behavior:
    """One behavior: layer weights, distance ring, path history, noise, altitude and options."""

    weights: dict[str, float] = field(default_factory=dict)
    name: str = ""
    description: str = ""
    r_e: float = 10.0  # exclusion radius (m): never choose closer than this
    r_i: float = 100.0  # inclusion radius (m): preference falls linearly to 0 here
    n: float = 0.01  # path-history recovery per decision tick
    noise: float = 1e-3  # amplitude of the seeded tie-breaking noise
    seed: int = 0
    altitude: float = 50.0  # waypoint z in the map frame (m)
    plugins: list[str] = field(default_factory=list)  # modules / .py files that register layers
    area: Area = Area()
    layers: LayerOptions = LayerOptions()
    schedule: list[SchedulePhase] = field(default_factory=list)
    retarget: Retarget = Retarget()
    terrain: Terrain = Terrain()
    flight: Flight = Flight()
    pattern: Pattern = Pattern()
    camera_pitch_deg: float | None = None  # the camera mount this behavior flies (None: the mission's)

    def __post_init__(self) -> None:
        if self.weights or not self.scripted:  # a pure pattern decides nothing and may weight nothing
            _check_weights(self.weights, "weights")
        elif self.pattern.then == "replan":
            raise ValueError("weights: pattern.then = 'replan' plans with the weights; give at least one")
        if self.camera_pitch_deg is not None and not 0.0 < self.camera_pitch_deg <= 90.0:
            raise ValueError(f"camera_pitch_deg = {self.camera_pitch_deg} is out of range (0, 90]")
        if not self.r_e >= 0:
            raise ValueError(f"r_e = {self.r_e} must be >= 0")
        if not self.r_i > self.r_e:
            raise ValueError(f"r_i = {self.r_i} must be > r_e = {self.r_e}")
        if not 0 <= self.n <= 1:
            raise ValueError(f"n = {self.n} is out of range [0, 1]")
        if not 0 <= self.noise <= 0.1:
            raise ValueError(f"noise = {self.noise} is out of range [0, 0.1]")
        _positive("altitude", self.altitude)

    @property
    def scripted(self) -> bool:
        """The pilot flies a pattern (``pattern.kind``) rather than deciding each waypoint."""
        return self.pattern.kind != "none"

    @property
    def deterministic(self) -> bool:
        """No decision noise touches the flight: a pattern that only repeats itself."""
        return self.scripted and self.pattern.then == "repeat"

    def summary(self) -> str:
        """The settings that shape this behavior's flight, in one line (a study names every behavior's)."""
        area = (f"circle r {self.area.radius:g} m" if self.area.shape == "circle"
                else f"polygon of {len(self.area.polygon)} vertices")
        mount = "the mission's pitch" if self.camera_pitch_deg is None else f"{self.camera_pitch_deg:g}° down"
        parts = [f"area {area}", f"altitude {self.altitude:g} m", f"camera {mount}"]
        if self.scripted:
            p = self.pattern
            front = "stereo baseline" if p.front_overlap is None else f"{p.front_overlap:g}"
            parts += [f"pattern {p.kind}", f"side overlap {p.side_overlap:g}"]
            if p.speed is None:
                parts.append(f"front overlap {front}")
            else:
                parts.append("speed autopilot default" if p.speed == 0 else f"speed {p.speed:g} m/s")
            if p.then == "replan":
                parts.append(f"then replan (stale after {p.stale_after:g} s)")
        if self.weights:
            parts.append("weights " + ", ".join(f"{k} {v:g}" for k, v in self.weights.items()))
            if not self.scripted:
                parts += [f"heading {self.flight.heading}", f"speed {self.flight.speed}",
                          f"view_stale_s {self.layers.view_stale_s:g}"]
        if self.terrain.enabled:
            parts.append(f"terrain following {self.terrain.clearance:g} m")
        return "; ".join(parts)

    @property
    def layer_names(self) -> list[str]:
        """Every layer any phase of this behavior weights (what must be computed)."""
        names = dict.fromkeys(self.weights)
        for phase in self.schedule:
            names.update(dict.fromkeys(phase.weights))
        return list(names)


def behavior_from_dict(data: dict, where: str = "behavior", base: Path | None = None) -> Behavior:
    """Validate a behavior table; imports its plugins, then checks every weighted layer exists.

    Explicit metres win: a table without r_e, r_i and ``flight.hops`` hops with the footprint.
    """
    flight = data.get("flight", {})
    if "r_e" not in data and "r_i" not in data and isinstance(flight, dict) and "hops" not in flight:
        data = {**data, "flight": {**flight, "hops": "footprint"}}
    behavior = from_dict(Behavior, data, where)
    try:
        load_plugins(behavior.plugins, base)
    except ValueError as exc:
        raise ConfigError(f"{where}.{exc}") from None
    known = set(layer_names())
    tables = [(f"{where}.weights", behavior.weights)]
    tables += [(f"{where}.schedule[{i}].weights", p.weights) for i, p in enumerate(behavior.schedule)]
    for key, weights in tables:
        for name in weights:
            if name not in known:
                raise ConfigError(f"{key}.{name}: no layer named {name!r}; known: {', '.join(sorted(known))}")
    return behavior


def preset_names() -> list[str]:
    return sorted(p.stem for p in PRESET_DIR.glob("*.toml"))


def load_behavior(name_or_path: str | Path) -> Behavior:
    """A preset by name (``balanced``) or a behavior file by path; ConfigError names the bad key."""
    path = Path(name_or_path)
    if path.suffix != ".toml":
        if not (PRESET_DIR / f"{path}.toml").is_file():
            raise ConfigError(f"behavior {str(name_or_path)!r}: not a file and not a preset ({', '.join(preset_names())})")
        path = PRESET_DIR / f"{path}.toml"
    data = load_toml(path)
    data.setdefault("name", path.stem)
    try:
        return behavior_from_dict(data, "behavior", path.parent)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
