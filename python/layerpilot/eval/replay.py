"""Offline replay of a mission recording, lock-step: "what would another behavior have chosen on this flight?"

The recorded clouds go, in the order they travelled, into the mission core's MapService (the
object the live map server drives), so ``map_only`` rebuilds the live map voxel for voxel.
With a behavior, the flown poses are the clock and the position: every ``1 / layers_rate``
mission seconds the map's layer set goes through the bus codec, as the map server publishes
it, to a Pilot of that behavior, asked afresh (no target of its own: the drone never flew
its choices) where it would fly from where the drone was. Its path history is the flown path.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from layerpilot.bus import layerset as wire
from layerpilot.bus import messages as msg
from layerpilot.bus.recording import RecordingReader
from layerpilot.bus.reject import BadMessage
from layerpilot.config import ConfigError, from_dict
from layerpilot.missionfile import Mission, load_mission
from layerpilot.mission.pipeline import MissionPipeline
from layerpilot.progress import Progress


@dataclass
class ReplayResult:
    out: Path
    map_path: Path
    clouds: int  # clouds inserted
    rejected: int  # recorded messages that did not decode
    damage: str  # "" when the recording was read to its end
    unknown_schemas: dict[str, int]
    decisions: list[dict] = field(default_factory=list)  # the replayed behavior's choices
    flown: list[dict] = field(default_factory=list)  # the recorded decisions (what the live pilot chose)
    path: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # flown positions (t, x, y)
    pictures: dict[str, Path] = field(default_factory=dict)


def recorded_mission(reader: RecordingReader, fallback: str | Path | None = None) -> Mission:
    """The mission the recording was flown with (kept in its metadata), or ``fallback`` (a file or name)."""
    if fallback is not None:
        return load_mission(fallback)
    for _ in reader.messages():  # the metadata is written first: stop at the first message
        break
    if not reader.mission_text:
        why = reader.damage or "no layerpilot mission in its metadata"
        raise ConfigError(f"{reader.path}: the recording holds no mission ({why}); give one with --config")
    return from_dict(Mission, tomllib.loads(reader.mission_text), "mission")


def replay(recording: str | Path, out: str | Path, *, mission: Mission | None = None, behavior: str | None = None,
           vehicle: str | None = None, progress_stream: TextIO | None = None) -> ReplayResult:
    """Rebuild the map from ``recording`` into ``out/map.ot``; with ``behavior``, also its choices at each
    layer tick (``out/decisions.jsonl``) and the pictures comparing them with the flown path."""
    reader = RecordingReader(recording)
    mission = mission or recorded_mission(RecordingReader(recording))
    vehicle = vehicle or mission.vehicles[0]
    if vehicle not in mission.vehicles:
        raise ValueError(f"--vehicle {vehicle!r}: the mission's vehicles are {mission.vehicles}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    mission = dataclasses.replace(mission, map_server=dataclasses.replace(mission.map_server, snapshot=""))
    if behavior is not None:
        mission = dataclasses.replace(mission, decide=dataclasses.replace(mission.decide, behavior=behavior))
    pipeline = MissionPipeline(mission.core, {"map", "decide"} if behavior is not None else {"map"}, [vehicle])
    period = 1.0 / mission.map_server.layers_rate
    next_tick = 0.0
    rejected, clouds, own_clouds = 0, 0, 0
    decisions, flown, path = [], [], []
    progress = Progress(max(1, reader.size) / 1e6, f"replay {reader.path.name}", " MB", progress_stream)
    for i, m in enumerate(reader.messages()):
        try:
            if m.topic == "cloud":
                c = msg.decode_cloud(m.data)
                if c.vehicle in mission.vehicles:  # as the map server: the mission's vehicles only
                    pipeline.cloud(c.vehicle, c.cloud, c.max_range or None)
                    clouds += 1
                    own_clouds += c.vehicle == vehicle
            elif m.topic == "decision" and m.key.split("/")[1] == vehicle:
                flown.append(_decision_record(msg.decode_decision(m.data)))
            elif m.topic == "pose" and m.key.split("/")[1] == vehicle:
                state = msg.decode_state(m.data)
                path.append((state.stamp, *state.position[:2]))
                if behavior is not None and state.stamp >= next_tick - 1e-9:
                    next_tick = state.stamp + period
                    decisions.append(_choose(pipeline, vehicle, state))
        except (BadMessage, ValueError) as exc:  # a recorded message that does not decode or insert
            rejected += 1
            if rejected == 1:
                logging.getLogger("layerpilot.replay").warning("replay: skipped a bad message on %s: %s", m.key, exc)
        if i % 64 == 0:
            progress.update(reader.position / 1e6, f"{clouds} clouds")
    progress.close(f"{clouds} clouds, {len(decisions)} replayed decisions")
    map_path = out / "map.ot"
    pipeline.map.map.save(map_path)
    result = ReplayResult(out, map_path, clouds, rejected, reader.damage, dict(reader.unknown_schemas),
                          decisions, flown, np.array(path).reshape(-1, 3))
    if behavior is not None and not (path and own_clouds):  # nothing to decide on, nothing to draw
        raise ValueError(f"recording {reader.path}: holds {len(path)} poses and {own_clouds} clouds of vehicle "
                         f"{vehicle!r}: nothing to replay --behavior on (--vehicle: one of {mission.vehicles})")
    if behavior is not None:
        with open(out / "decisions.jsonl", "w") as f:
            for record in decisions:
                f.write(json.dumps(record, default=lambda v: np.asarray(v).tolist()) + "\n")
        from layerpilot.eval.pictures.replay import plot_replay

        columns = pipeline.map.columns()
        result.pictures["comparison"] = plot_replay(columns, result.path[:, 1:], flown, decisions,
                                                    out / "replay.png", f"flown ({mission.decide.behavior}) vs "
                                                    f"replayed ({behavior})")
    return result


def _choose(pipeline: MissionPipeline, vehicle: str, state: msg.State) -> dict:
    """The pilot's choice from the drone's recorded position, on the layer set as the map server sends it."""
    pipeline.pose(vehicle, state.stamp, state.pose)
    view = pipeline.layers(vehicle)
    message = wire.encode_columns(view.columns, view.stamp, vehicle, pipeline.mission.map_server.layers)
    columns = wire.to_column_layers(wire.decode_layer_set(message))
    pipeline.pilots[vehicle].target = None  # asked afresh at every tick: the drone never flew the replayed choices
    position = tuple(float(v) for v in state.position)
    command = pipeline.tick(vehicle, state.stamp, columns)
    record = {"time": state.stamp, "position": list(position)}
    if command is not None:
        record.update(command.record())
        record["time"] = state.stamp
    return record


def _decision_record(d: msg.Decision) -> dict:
    return {"time": d.stamp, "seq": d.seq, "waypoint": d.waypoint.tolist(), "score": d.score,
            "behavior": d.behavior}

