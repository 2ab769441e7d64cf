"""The decision node: layer sets + pose in, decisions, waypoints and mission state out.

Zenoh callbacks only keep the newest layer set and pose; one worker makes a decision
tick when there is no target yet or the drone has arrived (within ``arrival_radius``),
stamped with the pose's mission clock. Other vehicles' current targets, heard on
``layerpilot/*/decision``, are passed to the maker as points to avoid. The current
waypoint is re-sent every second, so a link that (re)starts later still gets it.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

import numpy as np
import zenoh

from layerpilot.bus import keys
from layerpilot.bus.guard import guarded
from layerpilot.bus.layerset import LayerSet as BusLayerSet
from layerpilot.bus.layerset import decode_layer_set, to_column_layers
from layerpilot.bus.messages import (Decision, MissionState, State, Term, Waypoint, decode_decision, decode_state,
                                     encode_decision, encode_mission_state, encode_waypoint)
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.bus.session import publish
from layerpilot.config import check_range
from layerpilot.decide.behavior import load_behavior
from layerpilot.decide.maker import DecisionMaker
from layerpilot.layers import LayerContext, compute_layers

_log = logging.getLogger("layerpilot.decide")
REPEAT_PERIOD = 1.0  # s: the current waypoint is re-sent this often until reached


@dataclass(frozen=True)
class DecideConfig:
    """The ``[decide]`` table of a mission file (one per vehicle)."""

    behavior: str = "balanced"  # preset name or .toml path
    arrival_radius: float = 3.0  # m (horizontal): the target counts as reached
    home: tuple[float, float] = (0.0, 0.0)
    speed: float = 0.0  # m/s sent with each waypoint, 0 = autopilot default

    def __post_init__(self) -> None:
        check_range("decide.arrival_radius", self.arrival_radius, 0.1)
        check_range("decide.speed", self.speed, 0.0)


class DecideNode:
    def __init__(self, session: zenoh.Session, vehicle: str, cfg: DecideConfig) -> None:
        self.session, self.keys, self.cfg = session, keys.Keys(vehicle), cfg
        behavior = load_behavior(cfg.behavior)
        self.behavior = behavior
        self.maker = DecisionMaker(behavior, home=cfg.home)
        self.rejects = Rejects(_log)
        self._layers: BusLayerSet | None = None
        self._state: State | None = None
        self._others: dict[str, np.ndarray] = {}  # vehicle -> its current target (x, y)
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._decls: list = []
        self._thread = threading.Thread(target=self._loop, name="decide", daemon=True)
        self.seq = 0
        self.reached = 0
        self.distance_flown = 0.0
        self.target: np.ndarray | None = None
        self._waypoint_msg: bytes | None = None

    def start(self) -> None:
        s, k = self.session, self.keys
        self._decls = [
            s.declare_subscriber(k.layers, guarded(decode_layer_set, self._on_layers, self.rejects)),
            s.declare_subscriber(k.pose, guarded(decode_state, self._on_state, self.rejects)),
            s.declare_subscriber(keys.all_vehicles("decision"), guarded(decode_decision, self._on_other, self.rejects)),
        ]
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        for d in self._decls:
            d.undeclare()
        self._thread.join()

    def _on_layers(self, ls: BusLayerSet, key: str) -> None:
        try:
            to_column_layers(ls)  # all five column arrays, consistent: else reject now, not in the worker
        except BadMessage as exc:
            self.rejects.reject(key, exc)
            return
        with self._cond:
            self._layers = ls
            self._cond.notify()

    def _on_state(self, state: State, key: str) -> None:
        with self._cond:
            if self._state is not None:
                self.distance_flown += float(np.linalg.norm(state.position - self._state.position))
            self._state = state
            self._cond.notify()

    def _on_other(self, d: Decision, key: str) -> None:
        if d.vehicle != self.keys.vehicle:
            with self._cond:
                self._others[d.vehicle] = d.waypoint[:2].copy()

    def _loop(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._stop.is_set() or self._due(), timeout=REPEAT_PERIOD)
                if self._stop.is_set():
                    return
                if not self._due():
                    repeat = self._waypoint_msg
                    if repeat is not None:  # a link that started (or restarted) late still gets its target
                        publish(self.session, self.keys.waypoint, repeat)
                    continue
                ls, state, avoid = self._layers, self._state, list(self._others.values())
            try:
                self._tick(ls, state, avoid)
            except ValueError as exc:  # e.g. the layer window misses the area of interest
                self.rejects.reject(self.keys.layers, BadMessage("decision failed", str(exc)))
                with self._cond:
                    self._layers = None  # wait for the next layer set

    def _due(self) -> bool:
        if self._layers is None or self._state is None:
            return False
        pos = self._state.position
        if self.target is None:
            return True
        if np.hypot(*(pos[:2] - self.target[:2])) <= self.cfg.arrival_radius:
            self.reached += 1
            self.target = None
            return True
        return False

    def _tick(self, ls: BusLayerSet, state: State, avoid: list[np.ndarray]) -> None:
        columns = to_column_layers(ls)
        pos = state.position
        context = LayerContext(now=state.stamp, home=self.cfg.home, position=tuple(float(v) for v in pos),
                               options=self.behavior.layers)
        layers = compute_layers(columns, context, self.behavior.layer_names)
        d = self.maker.decide(layers, pos, state.stamp, avoid=[tuple(a) for a in avoid])
        self.seq += 1
        wp = np.asarray(d.waypoint, np.float64)
        self.target = wp
        terms = tuple(Term(n, d.weights.get(n, 0.0), (c / d.weights[n]) if d.weights.get(n) else 0.0, c)
                      for n, c in d.contributions.items())
        terms += (Term("zone", 1.0, d.zone, d.zone), Term("preference", 1.0, d.preference, d.preference),
                  Term("history", 1.0, d.history, d.history))
        v = self.keys.vehicle
        publish(self.session, self.keys.decision, encode_decision(
            Decision(state.stamp, v, self.seq, wp, d.score, terms, self.behavior.name)))
        self._waypoint_msg = encode_waypoint(Waypoint(state.stamp, v, self.seq, wp, speed=self.cfg.speed))
        publish(self.session, self.keys.waypoint, self._waypoint_msg)
        publish(self.session, self.keys.state, encode_mission_state(MissionState(
            state.stamp, v, "survey", self.seq, self.reached, self.distance_flown, wp)))
        _log.info("%s", d.explain())
