"""A survey's state between flights: saved by the pilot's driver, loaded by ``up --resume``.

What a battery swap must not lose: the path history (rebuilt by replaying every decision
tick's position through the decision maker's own :class:`PathHistory`, so it is the very same
float32 H), the weight schedule's phase, the decision noise's generator, the command count,
the arrivals, the last target and the mission time flown. The map comes back from the map
server's newest snapshot (``map_server.snapshot``), which it reloads at start.

After a resume the pilot chooses afresh from where the drone is (reason ``resume``): the
decision maker with the restored history and phase, a pattern from the leg it was flying.
The resumed flight's stamps go on from the newest saved mission time (:func:`clock_after`,
mission.clock). The state also names the mission run that saved it (``mission_id``, one per
`up`): a decide node that `up` restarts after a crash continues its predecessor's state,
even its battery return; a new run starts fresh unless resumed.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from layerpilot.grid import GridGeometry
from layerpilot.mission.clock import MissionClock
from layerpilot.mission.pilot import Pilot

VERSION = 1


def state_file(directory: str | Path, vehicle: str) -> Path:
    """Where the state of ``vehicle``'s survey lives (``decide.state`` is the directory)."""
    return Path(directory) / f"{vehicle}.json"


def clock_after(directory: str | Path, vehicles: list[str] | tuple[str, ...]) -> MissionClock:
    """The clock of the flight that resumes the survey saved in ``directory``: on from the newest
    mission time any of ``vehicles`` saved (one clock for all, as the map server's cells share it)."""
    clocks = [MissionClock()]
    for vehicle in vehicles:
        path = state_file(directory, vehicle)
        try:  # the clock too: a NaN or negative time is this file's damage
            clocks.append(MissionClock(float(json.loads(path.read_text())["time"])))
        except FileNotFoundError:
            continue
        except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: damaged mission state: {type(exc).__name__}: {exc}") from None
    return max(clocks, key=lambda clock: clock.start)


def saved_mission_id(path: str | Path) -> str:
    """The mission run (``mission_id``) that saved ``path``; "" if none or unreadable (then nothing continues)."""
    try:
        return str(json.loads(Path(path).read_text()).get("mission_id", ""))
    except (OSError, json.JSONDecodeError, AttributeError):
        return ""


def set_aside(path: str | Path) -> Path | None:
    """Keep a state that a new survey would overwrite as ``<vehicle>.json.bak`` (replacing an older one);
    returns where it went, None if there was none. `up` without --resume after a battery swap is then
    undone by renaming it back and `up --resume`."""
    path = Path(path)
    if not path.exists():
        return None
    kept = path.with_name(path.name + ".bak")
    os.replace(path, kept)
    return kept


def snapshot(pilot: Pilot, time: float, flown_s: float, mission_id: str = "") -> dict[str, Any]:
    """The pilot's survey state as plain JSON-ready data; ``time`` is the newest mission-clock stamp."""
    maker = pilot.maker
    return {"version": VERSION, "behavior": pilot.cfg.behavior, "time": float(time), "flown_s": float(flown_s),
            "mission_id": mission_id,
            "seq": pilot.seq, "reached": pilot.reached, "ending": pilot.ending,
            "target": None if pilot.target is None else [float(v) for v in pilot.target],
            "next_pattern": pilot._next_pattern,
            "route": None if pilot.route is pilot.pattern else pilot.route.tolist(),  # a replanned flight
            "schedule_phase": None if maker is None else maker.schedule.phase,
            "rng": None if maker is None else maker.rng.bit_generator.state,
            "ticks": [list(t) for t in pilot.ticks]}


def save(pilot: Pilot, path: str | Path, time: float, flown_s: float, mission_id: str = "") -> None:
    """Write the state atomically (a crash mid-write leaves the previous file whole)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(snapshot(pilot, time, flown_s, mission_id)))
    os.replace(tmp, path)


def load(pilot: Pilot, path: str | Path, same_flight: bool = False) -> dict[str, Any]:
    """Restore a fresh pilot from ``path``; returns the saved state. ValueError names what is wrong
    (a missing or damaged file, another behavior's state). ``same_flight``: a restarted node of the
    same flight (the battery is the same: a battery return stays the flight's end); else a new
    flight after a battery swap, which may survey again."""
    path = Path(path)
    try:
        state = json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: no saved mission state to resume (decide.state)") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: damaged mission state: {exc}") from None
    try:
        _restore(pilot, state)
        pilot.ending = str(state["ending"]) if same_flight else ""
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: damaged mission state: {type(exc).__name__}: {exc}") from None
    return state


def _restore(pilot: Pilot, state: dict[str, Any]) -> None:
    if state["version"] != VERSION:
        raise ValueError(f"version {state['version']}, this layerpilot reads {VERSION}")
    if state["behavior"] != pilot.cfg.behavior:
        raise ValueError(f"saved by behavior {state['behavior']!r}, the mission flies {pilot.cfg.behavior!r}")
    if pilot.seq or pilot.ticks:
        raise ValueError("the pilot has flown already: resume a fresh one")
    ticks = [tuple(float(v) for v in t) for t in state["ticks"]]
    if any(len(t) != 7 or not all(math.isfinite(v) for v in t) for t in ticks):
        raise ValueError("ticks: expected finite (x, y, origin_x, origin_y, resolution, width, height) each")
    maker = pilot.maker
    if (maker is None) != (state["schedule_phase"] is None):
        raise ValueError("a pattern's state for a decision maker, or the other way round")
    if maker is not None:
        for x, y, *g in ticks:  # the same ticks as flown: the same H to the bit
            geometry = GridGeometry(g[0], g[1], g[2], int(g[3]), int(g[4]))
            maker.history.tick(geometry, _distance(geometry, x, y))
        phase = int(state["schedule_phase"])
        if not 0 <= phase <= len(maker.behavior.schedule):
            raise ValueError(f"schedule_phase: {phase} is not a phase of the behavior")
        maker.schedule.phase = phase
        maker.rng.bit_generator.state = state["rng"]
    pilot.ticks = ticks
    pilot.seq, pilot.reached = int(state["seq"]), int(state["reached"])
    # a pattern flies again the leg it was on; the decision maker chooses afresh from where the drone is
    pilot._next_pattern = max(0, int(state["next_pattern"]) - (state["target"] is not None))
    if state.get("route") is not None:
        route = np.asarray(state["route"], np.float64)
        if route.ndim != 2 or route.shape[1] != 4 or not np.all(np.isfinite(route)):
            raise ValueError("route: expected finite (x, y, z, yaw) rows")
        pilot.route = route
    pilot._waiting = "resume"


def _distance(geometry: GridGeometry, x: float, y: float) -> np.ndarray:
    """Metres from (x, y) to each cell centre, in float32 as the decision maker computes them."""
    xs, ys = geometry.cell_centers()
    dx = xs[:1].astype(np.float32) - np.float32(x)
    dy = ys[:, :1].astype(np.float32) - np.float32(y)
    d = dx * dx + dy * dy
    return np.sqrt(d, out=d)
