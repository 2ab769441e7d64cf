"""One scored mission in one process, in lock-step, driving the mission core's step objects.

camera -> depth service -> map service -> layer set (through the bus codec, as on the wire)
-> pilot -> MAVLink -> simulated vehicle. The pilot, map service and depth service are the
very objects the live nodes call (``layerpilot.mission``), built from the same mission file,
so what the study scores is what flies. Waypoints reach the simulated vehicle through the
real flight link (``FlightLink``) over MAVLink on a loopback TCP port.

The map service publishes a layer set every ``1 / map_server.layers_rate`` mission seconds
and the pilot steps on every simulator step with the newest one, as the decide node does
with the newest layer set and pose it heard. Everything is a function of the seeds: the
take-off (connect, pre-arm, GUIDED, arm, NAV_TAKEOFF over MAVLink) is paced by the link's
wall-clock waits and is not scored; when it is done the vehicle is placed exactly at the
hover point (0, 0, altitude) at rest with a full battery and the mission clock starts at 0
there. Two runs with the same mission are identical to the bit. The pilot hears the battery
as the autopilot reports it (SYS_STATUS's whole percent, read from the endpoint in step);
once it turns home for the battery the mission ends when it is there (``ended`` in the report).

Frames: as in a live mission, the map frame is the autopilot's local frame, with its origin
at the EKF origin on the ground at home (the decide behavior's altitude is a height above
home). The simulator renders in its world's frame; the camera frames and the pilot's position
are moved into the map frame by the endpoint's ``ekf_origin``, as the live sim node does.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TextIO

import numpy as np

from layerpilot.eval.alignment import MapScorer
from layerpilot.eval.series import SAMPLE_INTERVAL, SeriesSampler
from layerpilot.eval.summary import write_run_report
from layerpilot.mission.config import Mission, to_settings
from layerpilot.mission.pilot import Command
from layerpilot.progress import Progress


@dataclass(frozen=True)
class PilotInput:
    """What the pilot looked at when it evaluated the layers: enough to replay its decisions."""

    time: float
    position: tuple[float, float, float]
    layer_set: bytes  # the wire message, exactly as the decide node would receive it
    command: Command | None  # what the pilot answered


@dataclass
class MissionResult:
    run_dir: Path
    final: dict[str, float]
    waypoints: int
    frames: int
    clouds: int
    wall_s: float
    report: dict[str, Path] = field(default_factory=dict)
    pilot_inputs: list[PilotInput] = field(default_factory=list)  # filled when asked to record them


def _take_off(sim, link, altitude: float, cruise_speed: float | None) -> None:
    """Connect, arm, take off and set the cruise speed over MAVLink; the simulator steps meanwhile."""
    done = threading.Event()
    error: list[BaseException] = []

    def fly() -> None:
        try:
            link.connect()
            link.wait_ready()
            link.start_guided()
            link.arm()
            link.takeoff(altitude)  # the link's frame: metres above home on the ground
            if cruise_speed is not None:
                link.set_speed(cruise_speed)
        except BaseException as exc:  # reported in the mission thread
            error.append(exc)
        finally:
            done.set()

    thread = threading.Thread(target=fly, name="mission-takeoff", daemon=True)
    thread.start()
    while not done.is_set():  # 40x real time while the link waits on the wall clock
        sim.endpoint.step(sim.config.step_s)
        done.wait(sim.config.step_s / 40)
    thread.join()
    if error:
        raise RuntimeError(f"take-off over MAVLink failed: {error[0]}") from error[0]


def flight_link(mission: Mission, url: str):
    """The evaluator's flight link to the simulated vehicle, with the mission's geofence, as the live link
    node has it. Heartbeats come at 1 Hz of mission time; a slow lock-step frame must not look like a lost link."""
    from layerpilot.link.config import LinkConfig
    from layerpilot.link.link import FlightLink
    from layerpilot.mission.build import geofence_for

    return FlightLink(LinkConfig(url=url, heartbeat_timeout_s=600.0), geofence=geofence_for(mission))


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def run_mission(mission: Mission, run_dir: str | Path, progress_stream: TextIO | None = None, *,
                record_inputs: bool = False, view=None) -> MissionResult:
    """Fly the mission's first vehicle and write the run directory (report, metrics, plots, maps, decisions).

    ``view``: a ``viz.lockstep.LockstepView`` that is shown the run as it flies (None: no view, no rerun).
    """
    from layerpilot.bus import layerset as wire
    from layerpilot.decide import area_geometry, zone_mask
    from layerpilot.depth.source import GroundTruthDepth
    from layerpilot.layers import compute_layers
    from layerpilot.link.link import WaypointRefused
    from layerpilot.map import VoxelMap
    from layerpilot.mission import resume as survey
    from layerpilot.mission.build import build_depth_service, build_pilot
    from layerpilot.mission.map_service import MapService
    from layerpilot.sim.simulator import Simulator

    wall0 = time.monotonic()
    out = Path(run_dir)
    out.mkdir(parents=True, exist_ok=True)
    ev, vehicle = mission.evaluation, mission.vehicles[0]
    pilot = build_pilot(mission)
    service = MapService(replace(mission.map_server, snapshot=""))  # the run directory gets the map
    depth = build_depth_service(mission)
    truth, gt = GroundTruthDepth(), VoxelMap(mission.map_server.resolution)  # the reference the map is scored on
    home = mission.decide.home
    geometry = area_geometry(pilot.behavior.area, home, resolution=mission.map_server.resolution)
    aoi = zone_mask(pilot.behavior.area, geometry, home) > 0.5
    if view is not None:
        view.start(pilot.behavior, home, geometry)
    xmin, xmax, ymin, ymax = geometry.extent
    box_min, box_max = np.array([xmin, ymin, -1000.0]), np.array([xmax, ymax, 1000.0])
    scorer = MapScorer(geometry, aoi, box_min, box_max)  # aligned to the truth and absolute, with the offset
    sampler = SeriesSampler(scorer.names, SAMPLE_INTERVAL)
    sim_cfg = replace(mission.sim, step_s=ev.step_s, urls=("tcp:127.0.0.1:0",))
    frame_period, layer_period = 1.0 / mission.sim.frame_rate_hz, 1.0 / mission.map_server.layers_rate
    frames = 0
    path: list[tuple[float, float]] = []
    records: list[dict] = []
    inputs: list[PilotInput] = []
    with Simulator(sim_cfg) as sim:
        host, port = sim.endpoint.addresses[0]
        link = flight_link(mission, f"tcp:{host}:{port}")
        try:
            altitude = pilot.behavior.altitude
            _take_off(sim, link, altitude, pilot.cruise_speed or None)
            origin = np.asarray(sim.endpoint.ekf_origin, float)  # the map frame's origin in the world
            hover = np.array([home[0], home[1], altitude])
            link.set_waypoint(*hover, yaw=0.0)
            sim.endpoint.step(ev.step_s)
            v = sim.vehicle
            v.position[:], v.velocity[:], v.acceleration[:], v.yaw, v.yaw_rate = hover + origin, 0.0, 0.0, 0.0, 0.0
            sim.endpoint.battery.swap()  # full at the mission clock's 0: the wall-paced take-off must not count
            steps = 0  # the mission clock is steps * step_s: exact, whatever the take-off took
            progress = Progress(ev.duration, f"{mission.decide.behavior} mission", "s", progress_stream)
            next_frame = next_layers = t = 0.0
            columns = message = None

            def metrics(now: float) -> dict[str, float]:
                return scorer(service.map, gt, now)

            while True:
                if t >= next_layers - 1e-9:  # the map server's layer set, through the wire codec
                    next_layers += layer_period
                    at = sim.endpoint.reported_pose().position - origin  # in full around the drone, as the node's
                    message = wire.encode_columns(service.columns(), service.last_stamp, vehicle,
                                                  mission.map_server.layers,
                                                  service.detail(at[0], at[1], pilot.layer_reach))
                    columns = wire.to_column_layers(wire.decode_layer_set(message))
                position = sim.endpoint.reported_pose().position - origin  # in the map frame, as reported
                evaluations = pilot.evaluations
                charge = round(100 * sim.endpoint.battery.remaining) / 100  # SYS_STATUS's whole percent
                command = pilot.step(position, t, columns, battery=charge)
                if record_inputs and pilot.evaluations != evaluations:
                    inputs.append(PilotInput(t, tuple(float(c) for c in position), message, command))
                if command is not None:
                    record = command.record()
                    try:
                        link.set_waypoint(*command.position, yaw=command.yaw)
                    except WaypointRefused as exc:  # as in the link node: refused, counted, the vehicle keeps on
                        record["refused"] = str(exc)
                        if link.refused[exc.kind] == 1:
                            logging.getLogger("layerpilot.eval").warning("waypoint refused by the link: %s", exc)
                    records.append(record)
                    if view is not None:  # with the tick's A0..A3 when the maker chose it
                        view.decision(t, record, None if command.decision is None else pilot.maker.last_tick)
                if t >= next_frame - 1e-9:
                    next_frame += frame_period
                    capture = sim.capture(now=t)  # what the drone delivers; its truth is for scoring only
                    pose, frame = capture.vehicle, capture.frame.seen_from(origin)
                    frames += 1
                    path.append(tuple(float(c) for c in (pose.position - origin)[:2]))
                    if view is not None:
                        view.frame(t, frame, pose.position - origin, service.map)
                    if (cloud := depth.push(frame)) is not None:
                        service.insert(cloud.points, cloud.origin, cloud.colors, t, mission.depth.max_depth)
                    if (reference := truth.push(capture.truth.seen_from(origin))) is not None and len(reference):
                        gt.insert(reference.points, reference.origin, reference.colors, stamp=t)
                if sampler.maybe_sample(t, lambda: metrics(t)) and view is not None:
                    view.metrics(t, sampler.series.last())
                last = sampler.series.last() if len(sampler.series) else {}
                progress.update(t, f"mapped {last.get('percent_mapped', 0.0):5.1f}% waypoints {len(records)}")
                if t >= ev.duration - 1e-9 or (pilot.ending and pilot.arrived(position)):
                    break  # the duration, or home after the pilot turned home (its flight is over)
                sim.endpoint.step(ev.step_s)
                steps += 1
                t = steps * ev.step_s
            if sampler.series.last()["t"] < t:
                sampler.series.append(t, metrics(t))
            progress.close(f"mapped {sampler.series.last()['percent_mapped']:.1f}% waypoints {len(records)}")
        finally:
            link.close()

    est = service.map
    est.save(out / "map.ot")
    survey.save(pilot, out / "survey.json", t, t)  # the pilot's state: `decide --resume` can go on from here
    est.export_bt(out / "map.bt")
    with open(out / "decisions.jsonl", "w") as f:
        for record in records:
            f.write(json.dumps(record, default=_json_default) + "\n")
    final_columns = est.column_layers_for(geometry)
    final_layers = compute_layers(final_columns, pilot.layer_context(final_columns, position, t),
                                  pilot.behavior.layer_names, est)
    images = dict(final_layers.layers)
    images["elevation_m"] = final_layers.elevation_m
    settings = {**to_settings(mission), "waypoints": len(records), "reached": pilot.reached,
                "ended": f"{pilot.ending}: {pilot.energy.why}; home at t = {t:.1f} s" if pilot.ending else "duration",
                "retargets": sum(r["reason"] == "retarget" for r in records),
                "geofence": link.geofence.describe(), "waypoints_refused": dict(link.refused),
                "frames": frames, "clouds": depth.clouds,
                **{f"depth_{k}": v for k, v in depth.stats().items()},  # why frames gave no cloud
                "wall_s": round(time.monotonic() - wall0, 1)}
    paths = write_run_report(out, f"layerpilot mission: {mission.decide.behavior}", sampler.series,
                             est.column_layers_for(geometry), aoi, np.array(path).reshape(-1, 2), images, settings)
    return MissionResult(out, sampler.series.last(), len(records), frames, depth.clouds,
                         time.monotonic() - wall0, paths, inputs)
