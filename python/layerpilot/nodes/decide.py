"""The decide node: layer sets + pose in, decisions, waypoints and mission state out.

The node only decodes and publishes; the mission's :class:`~layerpilot.mission.pilot.Pilot`
(the same object the lock-step evaluator drives) says when and where to fly. Zenoh
callbacks keep the newest layer set and pose; one worker steps the pilot on every new
input, stamped with the pose's mission clock. Other vehicles' current targets, heard on
``layerpilot/*/decision``, are points to avoid. The current waypoint is re-sent every
second, so a link that (re)starts later still gets it.

The decision's aggregate layers A0..A3 are offered, not sent: a queryable on
``layerpilot/<vehicle>/decide/aggregates`` answers with those of the last tick, on the window
the tick computed (its grid is that window's placement in the map frame). The worker only
keeps a reference to the tick's arrays; nothing is multiplied out or encoded unless a viewer asks.
"""

from __future__ import annotations

import logging
import functools
import math
import threading
import time
from pathlib import Path

import numpy as np
import zenoh

from layerpilot.bus import keys
from layerpilot.bus.guard import guarded
from layerpilot.bus.layerset import GridLayersMessage
from layerpilot.bus.layerset import decode_layer_set, encode_layer_set, to_column_layers
from layerpilot.bus.messages import (Decision, MissionState, State, Term, Waypoint, decode_decision, decode_state,
                                     decode_waypoint, encode_decision, encode_mission_state, encode_waypoint)
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.bus.session import publish
from layerpilot.decide.maker import TickTerms
from layerpilot.map.columns import ColumnLayers
from layerpilot.mission import resume as survey
from layerpilot.missionfile import geofence_for
from layerpilot.mission.energy import RETURN_PHASE
from layerpilot.missionfile import Mission
from layerpilot.mission.pilot import WAYPOINT_REPEAT_S, Command, fleet_targets
from layerpilot.mission.pipeline import MissionPipeline
from layerpilot.nodes.supervise import Supervisor

_log = logging.getLogger("layerpilot.decide")
INPUT_ERRORS = (ValueError, ArithmeticError)  # what a layer set or pose can provoke in the pilot: that input's fault
# A pose the drone cannot have: a stamp off the mission clock, or a place far outside the geofence.
# One such pose would poison the pilot's clock or path (its arrival, retarget and schedule times).
MAX_STAMP_S = 1e7  # s of mission clock (115 days)
POSE_SLACK_M = 500.0  # m outside the geofence's area
POSE_Z_RANGE = (-1000.0, 10_000.0)  # m, map frame
AGGREGATES = ("A0", "A1", "A2", "A3")


def encode_aggregates(tick: TickTerms, vehicle: str) -> bytes:
    """A tick's A0..A3 as a layer set whose grid is the tick's window (float16): the ``decide/aggregates``
    reply, and what the lock-step evaluator gives its view."""
    if tick.placement is None:
        raise ValueError("aggregates: the tick's window was empty (the drone was beyond the layers' grid)")
    return encode_layer_set(GridLayersMessage(tick.time, vehicle, tick.placement, tick.aggregates()),
                            dict.fromkeys(AGGREGATES, "float16"))


def decode_aggregates(payload: bytes, vehicle: str) -> GridLayersMessage:
    """A ``decide/aggregates`` reply: A0..A3 of ``vehicle`` and nothing else (BadMessage names what is wrong)."""
    ls = decode_layer_set(payload)
    if ls.vehicle != vehicle or sorted(ls.layers) != list(AGGREGATES):
        raise BadMessage("bad aggregates", f"expected A0..A3 of {vehicle}, got {sorted(ls.layers)} of {ls.vehicle}")
    return ls


def decision_message(command: Command, vehicle: str, behavior: str) -> Decision:
    """The bus form of a command's decision: every term of the score, for the operator and the other drones."""
    d = command.decision
    if d is None:  # a scripted pattern: no score to explain
        return Decision(command.time, vehicle, command.seq, np.array(command.position), 0.0, (), behavior)
    terms = tuple(Term(n, d.weights.get(n, 0.0), (c / d.weights[n]) if d.weights.get(n) else 0.0, c)
                  for n, c in d.contributions.items())
    terms += (Term("zone", 1.0, d.zone, d.zone), Term("preference", 1.0, d.preference, d.preference),
              Term("history", 1.0, d.history, d.history))
    runner_up = None if d.runner_up is None else np.array(d.runner_up.waypoint)
    return Decision(command.time, vehicle, command.seq, np.array(command.position), d.score, terms, behavior,
                    runner_up, d.explain())


class DecideNode:
    def __init__(self, session: zenoh.Session, vehicle: str, mission: Mission,
                 supervisor: Supervisor | None = None, resume: bool = False, mission_id: str = "") -> None:
        """``resume``: continue the survey saved in ``decide.state`` (ValueError if there is none), a new
        flight. ``mission_id``: the `up` run this node belongs to; a state saved by the same run (this
        node's predecessor, before it crashed) is continued as the same flight (``continued``), with or
        without ``resume``."""
        self.session, self.keys, self.mission = session, keys.Keys(vehicle), mission
        self._fence = geofence_for(mission)
        self.pipeline = MissionPipeline(mission.core, {"decide"}, [vehicle])
        self.pilot = self.pipeline.pilots[vehicle]
        self.mission_id = mission_id
        self.state_path = survey.state_file(mission.decide.state, vehicle) if mission.decide.state else None
        self.continued = bool(mission_id and self.state_path is not None  # also under --resume: a restart
                              and survey.saved_mission_id(self.state_path) == mission_id)
        self.resumed = survey.load(self.pilot, self._require_state(), same_flight=self.continued) \
            if resume or self.continued else None
        if not self.resumed and self.state_path is not None:  # a new survey: another run's saved one is kept
            saved_by = survey.saved_mission_id(self.state_path) or "unknown"
            if (kept := survey.set_aside(self.state_path)) is not None:
                _log.warning("a new survey (no --resume): the one saved by run %s is kept as %s (rename it back "
                             "and run `up --resume` to continue it)", saved_by, kept)
        self._flown_before = self.resumed["flown_s"] if self.resumed else 0.0  # mission s flown before this node
        # the same flight goes on: its time since the predecessor's last save was flown too
        self._first_stamp: float | None = self.resumed["time"] if self.continued else None
        if self.resumed:
            _log.warning("%s the survey saved at mission time %.1f s: %d decisions, %d reached%s",
                         "continuing (restarted)" if self.continued else "resuming", self.resumed["time"],
                         self.pilot.seq, self.pilot.reached,
                         f", ended: {self.pilot.ending}" if self.pilot.ending else "")
        self.rejects = Rejects(_log)
        self.supervisor = supervisor or Supervisor(_log)
        # a layer set is the map server's configured window: a larger grid is refused before it is decoded
        _, _, w, h = mission.map_server.window
        self._decode_layers = functools.partial(decode_layer_set, max_cells=int(w) * int(h))
        self._columns: ColumnLayers | None = None
        self._state: State | None = None
        self._fresh = False  # a new layer set or pose since the last step
        self._others: dict[str, np.ndarray] = {}  # vehicle -> its current target (x, y)
        self._heard: dict[str, float] = {}  # vehicle -> when its decision or repeated waypoint came (monotonic s)
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._decls: list = []
        self.distance_flown = 0.0
        self._waypoint_msg: bytes | None = None
        self._state_msg: bytes | None = None
        self._sent_at = 0.0
        self._tick: TickTerms | None = None  # the last tick's terms (by reference), for decide/aggregates
        self._tick_reply: tuple[TickTerms, bytes] | None = None  # encoded once per tick, when asked
        self.aggregates_answered = 0

    @property
    def seq(self) -> int:
        return self.pilot.seq

    @property
    def reached(self) -> int:
        return self.pilot.reached

    def start(self) -> None:
        s, k, r, sv = self.session, self.keys, self.rejects, self.supervisor
        self._decls = [
            s.declare_subscriber(k.layers, guarded(self._decode_layers, self._on_layers, r, sv)),
            s.declare_subscriber(k.pose, guarded(decode_state, self._on_state, r, sv)),
            s.declare_subscriber(keys.all_vehicles("decision"), guarded(decode_decision, self._on_other, r, sv)),
            s.declare_subscriber(keys.all_vehicles("waypoint"), guarded(decode_waypoint, self._on_other, r, sv)),
            s.declare_queryable(k.aggregates, self._on_aggregates),
        ]
        self.supervisor.start("decide", self._iteration)

    def stop(self) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        for d in self._decls:
            d.undeclare()
        self.supervisor.join()
        if self._state is not None:
            self._save(self._state.stamp)

    def _require_state(self) -> Path:
        if self.state_path is None:
            raise ValueError("--resume: decide.state is '' (no survey state is saved): nothing to resume")
        return self.state_path

    def _save(self, stamp: float) -> None:
        """The survey's state for `up --resume` (after every command and at the end)."""
        if self.state_path is not None:
            flown = self._flown_before + (0.0 if self._first_stamp is None else max(0.0, stamp - self._first_stamp))
            survey.save(self.pilot, self.state_path, stamp, flown, self.mission_id)

    def _on_layers(self, ls: GridLayersMessage, key: str) -> None:
        try:
            columns = to_column_layers(ls)  # all five column arrays, consistent: else reject now, not in the worker
        except BadMessage as exc:
            self.rejects.reject(key, exc)
            return
        with self._cond:
            self._columns, self._fresh = columns, True
            self._cond.notify()

    def _on_state(self, state: State, key: str) -> None:
        x, y, z = (float(v) for v in state.position[:3])
        if not 0.0 <= state.stamp <= MAX_STAMP_S:
            raise BadMessage("implausible pose", f"stamp {state.stamp} s on {key} is off the mission clock "
                                                 f"[0, {MAX_STAMP_S:g}]")
        outside = self._fence.distance_outside(x, y)
        if outside > POSE_SLACK_M or not POSE_Z_RANGE[0] <= z <= POSE_Z_RANGE[1]:
            raise BadMessage("implausible pose", f"position ({x:g}, {y:g}, {z:g}) on {key} is {outside:.0f} m "
                                                 f"outside the geofence or out of {POSE_Z_RANGE} m in height")
        with self._cond:
            if self._state is not None:
                self.distance_flown += float(np.linalg.norm(state.position - self._state.position))
            self._state, self._fresh = state, True
            self._cond.notify()

    def _on_other(self, d: Decision | Waypoint, key: str) -> None:
        """Another drone's decision, or its waypoint as its decide node repeats it (which keeps its target
        claimed: one silent for ``decide.claim_timeout_s`` dropped out and its target is free again)."""
        vehicle = keys.vehicle_of(key)
        if vehicle not in self.mission.vehicles or d.vehicle != vehicle:  # state only for the mission's vehicles
            raise BadMessage("unknown vehicle", f"{type(d).__name__.lower()} of {d.vehicle!r} on {key}: not one of "
                                                f"the mission's other vehicles {self.mission.vehicles}")
        if vehicle != self.keys.vehicle:
            target = d.waypoint if isinstance(d, Decision) else d.position
            with self._cond:
                self._heard[vehicle] = time.monotonic()
                old, self._others[vehicle] = self._others.get(vehicle), target[:2].copy()
                if old is None or not np.array_equal(old, self._others[vehicle]):  # a repeat is no news
                    self._fresh = True  # a drone with priority may have taken our target
                    self._cond.notify()

    def _iteration(self) -> bool:
        """Wait for a new layer set or pose (or the repeat period), step the pilot, publish; False = stop."""
        with self._cond:
            self._cond.wait_for(lambda: self._stop.is_set() or self._fresh, timeout=WAYPOINT_REPEAT_S)
            if self._stop.is_set():
                return False
            fresh, self._fresh = self._fresh, False
            columns, state = self._columns, self._state
            self._expire_claims()
            avoid, yield_to = fleet_targets(self.mission.vehicles, self.keys.vehicle, self._others,
                                            self.mission.decide.coordinate)
        self._repeat_waypoint()
        if not fresh or state is None:
            return True
        try:
            if self._first_stamp is None:
                self._first_stamp = state.stamp
            # the drain is measured in flight: a charge read on the ground, disarmed, would dilute it
            charge = state.battery if state.armed else math.nan
            self.pipeline.pose(self.keys.vehicle, state.stamp, state.pose)
            command = self.pipeline.tick(self.keys.vehicle, state.stamp, columns, avoid=avoid, yield_to=yield_to,
                                         battery=charge)
        except INPUT_ERRORS as exc:  # e.g. the layer window misses the area of interest: wait for the next one
            self.rejects.reject(self.keys.layers, BadMessage(f"decision failed ({type(exc).__name__})", str(exc)))
            with self._cond:
                if self._columns is columns:
                    self._columns = None
            return True
        if self.pilot.maker is not None:
            with self._cond:
                self._tick = self.pilot.maker.last_tick
        if command is not None:
            self._publish(command, state)
        return True

    def _on_aggregates(self, query: zenoh.Query) -> None:
        """A viewer asks for the last tick's A0..A3 (Zenoh's thread: one encoding per tick, a few ms)."""
        try:
            with self._cond:
                tick, reply = self._tick, self._tick_reply
            if tick is None:
                query.reply_err(b"no decision tick yet (or the behavior is a scripted pattern)")
                return
            if reply is None or reply[0] is not tick:
                reply = (tick, encode_aggregates(tick, self.keys.vehicle))
                with self._cond:
                    self._tick_reply = reply
            query.reply(self.keys.aggregates, reply[1])
            self.aggregates_answered += 1
        except Exception as exc:  # every query gets an answer; the first failure of a kind is logged
            self.supervisor.error("aggregates", exc)
            query.reply_err(f"aggregates: {type(exc).__name__}: {exc}".encode())
        finally:
            query.drop()

    def _expire_claims(self) -> None:
        """Forget the target of a drone not heard from for ``decide.claim_timeout_s`` (held: ``_cond``)."""
        now, timeout = time.monotonic(), self.mission.decide.claim_timeout_s
        for vehicle in [v for v, heard in self._heard.items() if now - heard > timeout]:
            del self._heard[vehicle], self._others[vehicle]
            _log.warning("%s not heard from for %g s: its target is free again", vehicle, timeout)

    def _repeat_waypoint(self) -> None:
        """A link that started (or restarted) late still gets its target (transport pacing: wall clock)."""
        if self._waypoint_msg is not None and time.monotonic() - self._sent_at >= WAYPOINT_REPEAT_S:
            publish(self.session, self.keys.waypoint, self._waypoint_msg)
            publish(self.session, self.keys.state, self._state_msg)  # a battery return, too, reaches a late link
            self._sent_at = time.monotonic()

    def _publish(self, command: Command, state: State) -> None:
        v, behavior = self.keys.vehicle, self.mission.decide.behavior
        publish(self.session, self.keys.decision, encode_decision(decision_message(command, v, behavior)))
        self._waypoint_msg = encode_waypoint(Waypoint(command.time, v, command.seq, np.array(command.position),
                                                      yaw=command.yaw, speed=command.speed))
        publish(self.session, self.keys.waypoint, self._waypoint_msg)
        self._sent_at = time.monotonic()
        phase = RETURN_PHASE if command.reason == "battery" else "survey"
        self._state_msg = encode_mission_state(MissionState(state.stamp, v, phase, command.seq, self.pilot.reached,
                                                            self.distance_flown, np.array(command.position)))
        publish(self.session, self.keys.state, self._state_msg)
        self._save(state.stamp)
        if command.reason == "battery":
            _log.warning("turning home: %s", self.pilot.energy.why)
        elif command.decision is not None:
            _log.info("%s", command.decision.explain())
        else:
            _log.info("%s waypoint %d: (%.1f, %.1f, %.1f)", behavior, command.seq, *command.position)
