"""The pilot: one step object that says where the drone flies next, whoever drives it.

The live decide node and the lock-step evaluator both call :meth:`Pilot.step` with the
newest pose, mission time and column layers; it returns a :class:`Command` when the drone
must fly somewhere new (first tick, target reached, or a better target while flying when
the behavior opts into retargeting) and ``None`` otherwise. Arrival is one rule
(horizontal distance to the target), and the choice is the MCDM decision maker or a
scripted pattern (a behavior's ``[pattern]``: survey lines, orbits, rings), so what the study scores
is what flies.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from layerpilot.config import check_range
from layerpilot.decide.behavior import Area, Behavior, Terrain, load_behavior
from layerpilot.decide.decision import Decision
from layerpilot.decide.area import zone_mask
from layerpilot.decide.maker import DecisionMaker
from layerpilot.decide.terrain import terrain_altitude
from layerpilot.layers import LayerContext, compute_layers
from layerpilot.layers.view_gain import CameraView
from layerpilot.grid import GridWindow
from layerpilot.map.columns import ColumnLayers
from layerpilot.mission.energy import HomeReturn
from layerpilot.mission.heading import HeadingPolicy

@dataclass(frozen=True)
class PilotConfig:
    """The ``[decide]`` table of a mission file (one per vehicle)."""

    behavior: str = "balanced"  # preset name (config/behaviors/, the scripted baselines too) or .toml path
    arrival_radius: float = 3.0  # m, horizontal: the target counts as reached
    home: tuple[float, float] = (0.0, 0.0)  # launch / operator point (map frame)
    speed: float = 0.0  # m/s sent with each MCDM waypoint, 0 = autopilot default (patterns set their own)
    seed: int | None = None  # decision noise seed; None = the behavior's
    battery_reserve: float = 0.25  # charge (0..1) to land with: the pilot turns home in time to keep it
    return_speed: float = 5.0  # m/s the way home is reckoned at (mission.energy)
    state: str = ""  # directory the survey's state is saved in, for `up --resume` (mission.resume); "" = none
    area: Area | None = None  # the area of interest this mission surveys, instead of the behavior's
    terrain: Terrain | None = None  # terrain following for whatever behavior flies (relief), instead of the behavior's
    altitude_layer: float = 10.0  # m: a fleet's k-th vehicle (from 0) flies k times this above the behavior's height
    coordinate: bool = True  # a fleet's pilots avoid each other's targets; false: each decides alone (a baseline)
    claim_timeout_s: float = 10.0  # s: a drone not heard from this long dropped out; its target is free again

    def __post_init__(self) -> None:
        check_range("decide.arrival_radius", self.arrival_radius, 0.1, 1000.0)
        check_range("decide.speed", self.speed, 0.0, 100.0)
        check_range("decide.battery_reserve", self.battery_reserve, 0.0, 0.9)
        check_range("decide.return_speed", self.return_speed, 0.1, 100.0)
        check_range("decide.altitude_layer", self.altitude_layer, 0.0, 100.0)
        check_range("decide.claim_timeout_s", self.claim_timeout_s, 0.5, 3600.0)
        self.flown_behavior()  # a bad name or file fails when the mission loads

    def flown_behavior(self, layer: int = 0) -> Behavior:
        """The behavior file with this mission's area of interest and terrain following, where the mission states
        them (``[decide.area]``, ``[decide.terrain]``); ``layer``: a fleet vehicle's place in the mission's list,
        flown ``layer * altitude_layer`` m higher (the terrain's clearance and floor too), so that drones whose
        paths cross pass at different heights."""
        behavior = load_behavior(self.behavior)
        if self.area is not None:
            behavior = dataclasses.replace(behavior, area=self.area)
        if self.terrain is not None:
            behavior = dataclasses.replace(behavior, terrain=self.terrain)
        if not (up := layer * self.altitude_layer):
            return behavior
        terrain = behavior.terrain
        return dataclasses.replace(behavior, altitude=behavior.altitude + up, terrain=dataclasses.replace(
            terrain, clearance=terrain.clearance + up, min_altitude=min(terrain.min_altitude + up, terrain.max_altitude)))


WAYPOINT_REPEAT_S = 1.0  # s: a driver re-sends the current waypoint this often until reached (a late link gets it)


def fleet_targets(vehicles: Sequence[str], me: str, targets: Mapping[str, Sequence[float]],
                  coordinate: bool = True) -> tuple[list[Sequence[float]], list[Sequence[float]]]:
    """``(avoid, yield_to)`` for ``me``'s pilot from the other drones' current targets (vehicle -> x, y):
    every other's to keep r_e from, and those of the vehicles listed before ``me`` in the mission, which
    have priority when two choose the same spot. Nothing with ``coordinate`` False (each decides alone)."""
    if not coordinate:
        return [], []
    others = [(v, t) for v, t in targets.items() if v != me]
    return [t for _, t in others], [t for v, t in others if vehicles.index(v) < vehicles.index(me)]


@dataclass(frozen=True)
class Command:
    """Fly to ``position`` (map frame) holding ``yaw`` (ENU rad) at ``speed`` m/s (0 = autopilot default)."""

    seq: int
    time: float
    position: tuple[float, float, float]
    yaw: float
    speed: float
    decision: Decision | None  # None for a scripted pattern (and its replanned flights) and the way home
    reason: str  # "start", "reached", "retarget", "conflict" (a drone with priority took our target), "resume",
    #              "battery" (home: the charge left needs it; the last command of the flight)

    def record(self) -> dict[str, Any]:
        """One JSON-ready line for decisions.jsonl (the same in every driver)."""
        out: dict[str, Any] = {"seq": self.seq, "time": self.time, "waypoint": list(self.position),
                               "yaw": self.yaw, "speed": self.speed, "reason": self.reason}
        if self.decision is None:
            out["scripted"] = self.reason != "battery"
        else:
            out.update(self.decision.to_dict())
            out["explanation"] = self.decision.explain()
        return out


class Pilot:
    """Arrival check, decision maker or pattern, retargeting; transport-free and deterministic.

    ``pattern``: (N, 4) waypoints x, y, z, yaw flown in a loop (a patrol), or None for MCDM;
    ``replan`` (columns, position, time) -> (M, 4) waypoints: what to fly once a pass of the pattern
    is done (its next flight over the gaps; none: the pattern again). With the behavior's terrain
    following on, each pattern waypoint's z clears the map's surface near the leg to it.
    ``view``: the camera at a candidate, for the view_gain layer (mission.flight.camera_view).
    """

    def __init__(self, cfg: PilotConfig, behavior: Behavior, *, pattern: np.ndarray | None = None,
                 pattern_speed: float = 0.0, seed: int | None = None, view: CameraView | None = None,
                 replan: Callable[[ColumnLayers, Sequence[float], float], np.ndarray] | None = None) -> None:
        self.cfg = cfg
        self.behavior = behavior
        self.heading = HeadingPolicy(behavior, cfg.home)
        self.view = view
        self._aoi: tuple[object, np.ndarray] | None = None  # (geometry, mask) of the last layer set
        self.pattern = self.route = pattern  # route: what is being flown (the pattern, or a replanned flight)
        self.pattern_speed = pattern_speed
        self.replan = replan
        self.replans = 0
        self.maker = None if pattern is not None else DecisionMaker(behavior, cfg.home, seed=seed)
        self.target: np.ndarray | None = None
        self.seq = 0
        self.reached = 0
        self.evaluations = 0  # decide + reconsider calls: when the pilot looked at the layers
        self._next_pattern = 0
        self._reconsidered: ColumnLayers | None = None
        self._waiting: str | None = None  # why a new command is due, while it waits for layers
        self.energy = HomeReturn(cfg.home, cfg.battery_reserve, cfg.return_speed)
        self.ending = ""  # "battery" once turned home: the flight's last command went out
        self.ticks: list[tuple[float, ...]] = []  # (x, y, *geometry) of each history tick, for mission.resume

    @property
    def cruise_speed(self) -> float:
        """The speed every command of this pilot carries (m/s, 0 = the autopilot's default)."""
        return self.pattern_speed if self.pattern is not None else self.cfg.speed

    @property
    def layer_reach(self) -> float:
        """How far from the drone a tick reads column layers (m): r_i, plus the camera's reach for view_gain."""
        return self.behavior.r_i + (self.view.reach if self.view is not None else 0.0)

    @property
    def retargets(self) -> bool:
        return self.maker is not None and self.behavior.retarget.enabled

    def arrived(self, position: Sequence[float]) -> bool:
        """Horizontal distance to the target within ``arrival_radius`` (the altitude is the autopilot's job)."""
        if self.target is None:
            return False
        return math.hypot(position[0] - self.target[0], position[1] - self.target[1]) <= self.cfg.arrival_radius

    def step(self, position: Sequence[float], time: float, columns: ColumnLayers | None,
             avoid: Sequence[Sequence[float]] = (), yield_to: Sequence[Sequence[float]] = (),
             battery: float = math.nan) -> Command | None:
        """A new command when one is due, else None. ``columns``: the newest column layers (None: none yet).

        ``battery``: the charge left (0..1, NaN unknown); once the way home plus ``battery_reserve``
        needs all of it, the command is home at the behavior's altitude (reason ``battery``) and
        nothing follows it (``ending``).

        ``avoid``: other drones' current targets (x, y); the maker keeps r_e away from them.
        ``yield_to``: those of drones with priority: when one of them chose a target within
        r_e of ours (both decided before hearing each other), we choose again.
        A retargeting behavior is reconsidered once per new ``columns`` object while flying.
        """
        if self.ending:
            return None
        if self.energy.due(position, time, battery):
            self.ending = "battery"
            home = (self.cfg.home[0], self.cfg.home[1], float(self.behavior.altitude))
            yaw = math.atan2(home[1] - position[1], home[0] - position[0])
            return self._command(time, home, yaw, 0.0, None, "battery")
        if self.target is None:
            reason = self._waiting or "start"
        elif self.arrived(position):
            self.reached += 1
            self.target, reason = None, "reached"  # counted once, even if the next choice must wait
        elif self.maker is not None and self._conflicts(yield_to):
            reason = "conflict"
        else:
            reason = None
        if reason is not None:
            self._waiting = reason
            if self.pattern is not None:
                return self._from_pattern(position, time, columns, reason)
            if columns is None or not self._covers(columns, position):
                return None
            self.evaluations += 1
            self._reconsidered = columns
            decision = self.maker.decide(self._layers(columns, position, time), position, time, avoid=avoid,
                                         widen=lambda window: self._layers(columns, position, time, window))
            g = columns.geometry  # the tick happened: remember where, for mission.resume
            self.ticks.append((float(position[0]), float(position[1]), g.origin_x, g.origin_y, g.resolution,
                               g.width, g.height))
            return self._from_decision(decision, position, time, reason)
        if (not self.retargets or columns is None or columns is self._reconsidered
                or not self._covers(columns, position)):
            return None
        self._reconsidered = columns
        self.evaluations += 1
        decision = self.maker.reconsider(self._layers(columns, position, time), position, time, avoid=avoid)
        return None if decision is None else self._from_decision(decision, position, time, "retarget")

    def _covers(self, columns: ColumnLayers, position: Sequence[float]) -> bool:
        """A windowed layer set (a large survey's) holds every cell this tick reads; else wait for one nearer."""
        return columns.window is None or columns.window.contains(self.maker.window(columns.geometry, position))

    def _conflicts(self, points: Sequence[Sequence[float]]) -> bool:
        return any(math.hypot(p[0] - self.target[0], p[1] - self.target[1]) < self.behavior.r_e for p in points)

    def layer_context(self, columns: ColumnLayers, position: Sequence[float] | None, time: float) -> LayerContext:
        """What the behavior's layers are computed with (also for the evaluator's final layer images)."""
        if self._aoi is None or self._aoi[0] != columns.geometry:
            self._aoi = (columns.geometry, zone_mask(self.behavior.area, columns.geometry, self.cfg.home) > 0.5)
        where = None if position is None else tuple(float(v) for v in position[:3])
        return LayerContext(now=time, home=self.cfg.home, position=where, options=self.behavior.layers,
                            view=self.view, aoi=self._aoi[1])

    def _layers(self, columns: ColumnLayers, position: Sequence[float], time: float,
                window: GridWindow | None = None):
        """The behavior's layers on the cells this tick can choose from (the maker's window), not the whole grid."""
        window = self.maker.window(columns.geometry, position) if window is None else window
        return compute_layers(columns, self.layer_context(columns, position, time), self.behavior.layer_names,
                              window=window)

    def _from_decision(self, d: Decision, position: Sequence[float], time: float, reason: str) -> Command:
        wp = tuple(float(v) for v in d.waypoint)
        return self._command(time, wp, self.heading.yaw(position, wp), self.cruise_speed, d, reason)

    def _from_pattern(self, position: Sequence[float], time: float, columns: ColumnLayers | None,
                      reason: str) -> Command | None:
        if self._next_pattern >= len(self.route):  # a pass is done: the next flight over the gaps, or again
            if self.replan is not None:
                if columns is None:
                    return None
                planned = self.replan(columns, position, time)
                self.replans += 1
                self.route = planned if len(planned) else self.pattern
            self._next_pattern = 0
        wp = self.route[self._next_pattern]
        self._next_pattern += 1
        z = float(wp[2])
        if self.behavior.terrain.enabled and columns is not None:
            z = terrain_altitude(columns.elevation, columns.geometry, (position[0], position[1]),
                                 (float(wp[0]), float(wp[1])), self.behavior.terrain, z)
        return self._command(time, (float(wp[0]), float(wp[1]), z), float(wp[3]), self.cruise_speed, None, reason)

    def _command(self, time: float, wp: tuple[float, float, float], yaw: float, speed: float,
                 decision: Decision | None, reason: str) -> Command:
        self.seq += 1
        self.target, self._waiting = np.array(wp), None
        return Command(self.seq, float(time), wp, float(yaw), float(speed), decision, reason)
