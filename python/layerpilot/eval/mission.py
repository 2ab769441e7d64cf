"""One scored mission in one process, in lock-step, driving the mission pipeline.

camera -> depth -> map -> layer set (through the bus codec, as on the wire) -> pilot -> MAVLink ->
simulated vehicle. The :class:`~layerpilot.mission.pipeline.MissionPipeline` is the object the live
nodes drive, built from the same mission file, so what the study scores is what flies; waypoints
reach the simulated vehicle through the real flight link (``FlightLink``) over MAVLink on a
loopback TCP port.

The map publishes a layer set every ``1 / map_server.layers_rate`` mission seconds and the pilot
steps on every simulator step with the newest one, as the decide node does with the newest layer
set and pose it heard. Everything is a function of the seeds: the take-off (connect, pre-arm,
GUIDED, arm, NAV_TAKEOFF over MAVLink) is paced by the link's wall-clock waits and is not scored;
when it is done the vehicle is placed exactly at the hover point (0, 0, altitude) at rest with a
full battery and the mission clock starts at 0 there. A fleet (``mission.vehicles``) flies every
vehicle so, each from its own simulator and link, the k-th ``START_SPACING * k`` m east of the
first. Two runs with the same mission are identical to the bit. The pilot hears the battery as the
autopilot reports it (SYS_STATUS's whole percent); once it turns home for the battery the mission
ends when it is there (``ended`` in the report).

Stages overlap where the data allows (``evaluation.overlap``): a frame's stereo and insertion run
on one worker and the ground-truth reference on another while the simulator flies on and renders
the next frame, and a metric sample is scored on a third from a snapshot of the maps; the main
thread waits for them only where their result is read (the next layer set, a metric sample's
snapshot, a view's map image, the end), so the results are byte-identical to the sequential order.

Frames: as in a live mission, the map frame is the autopilot's local frame, with its origin at the
EKF origin on the ground at home (the decide behavior's altitude is a height above home). The
simulator renders in its world's frame; the camera frames and the pilot's position are moved into
the map frame by the endpoint's ``ekf_origin``, as the live sim node does. Where the map frame
lies on the Earth (the EKF origin's latitude, longitude and altitude) goes into the run
directory's ``frame.json``, which `layers export` and `plan next` read.

The report's settings are the mission's, with the paths and addresses this run used in place of
the file's (its map and survey in the run directory, the loopback MAVLink port and the link it flew
with, the simulator's step).
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections import Counter, deque
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, TextIO, TypeVar

import numpy as np

from layerpilot.bus import layerset as wire
from layerpilot.decide import area_geometry, zone_mask
from layerpilot.depth.source import GroundTruthDepth
from layerpilot.eval.alignment import MapScorer, MapSnapshot
from layerpilot.eval.fleet import FleetTracker
from layerpilot.eval.milestones import time_to_percent
from layerpilot.eval.pose_errors import pose_errors
from layerpilot.eval.run_frame import write_run_frame
from layerpilot.eval.series import SAMPLE_INTERVAL, SeriesSampler
from layerpilot.eval.summary import write_run_report
from layerpilot.geodesy import LocalFrame
from layerpilot.geometry import CameraFrame, Pose
from layerpilot.layers import compute_layers
from layerpilot.link.config import LinkConfig
from layerpilot.link.link import FlightLink, WaypointRefused
from layerpilot.link.separation import Separation
from layerpilot.map import VoxelMap
from layerpilot.map.columns import ColumnLayers
from layerpilot.mission import resume as survey
from layerpilot.missionfile import geofence_for
from layerpilot.missionfile import Mission, to_settings
from layerpilot.mission.pilot import WAYPOINT_REPEAT_S, Command, fleet_targets
from layerpilot.mission.pipeline import MissionPipeline
from layerpilot.progress import Progress
from layerpilot.sim.simulator import Simulator

_log = logging.getLogger("layerpilot.eval")
T = TypeVar("T")
START_SPACING = 15.0  # m along x between a fleet's drones at the mission clock's 0
SENSOR_SEED_STRIDE = 1_000_003  # the i-th drone's sensor errors are seeded world seed + i * this


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


class Stages:
    """Work handed off the main thread, in order per lane; ``settle`` waits until the given lanes are done.

    ``overlap`` False runs each job at once in the caller: the sequential order, for comparison.
    """

    def __init__(self, lanes: tuple[str, ...], overlap: bool) -> None:
        self._pools = {lane: ThreadPoolExecutor(1, thread_name_prefix=f"mission-{lane}") for lane in lanes} \
            if overlap else {}
        self._pending: dict[str, list[Future]] = {lane: [] for lane in lanes}

    def submit(self, lane: str, job: Callable[[], T]) -> Future:
        """The job's future (done at once in the sequential order)."""
        if not self._pools:
            done: Future = Future()
            done.set_result(job())
            return done
        future = self._pools[lane].submit(job)
        self._pending[lane].append(future)
        return future

    def settle(self, *lanes: str) -> None:
        """Wait for ``lanes`` (every lane when none is named); a job's exception is raised here, in the
        mission thread."""
        for lane in lanes or tuple(self._pending):
            pending, self._pending[lane] = self._pending[lane], []
            for f in pending:
                f.result()

    def close(self) -> None:
        self.settle()
        for pool in self._pools.values():
            pool.shutdown()


def _take_off(sim: Simulator, link: FlightLink, altitude: float, cruise_speed: float | None) -> None:
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


def flight_link(mission: Mission, url: str, separation: Separation | None = None) -> FlightLink:
    """The evaluator's flight link to the simulated vehicle, with the mission's geofence (and a fleet's
    separation), as the live link node has it. Heartbeats come at 1 Hz of mission time; a slow lock-step
    frame must not look like a lost link."""
    return FlightLink(LinkConfig(url=url, heartbeat_timeout_s=600.0), geofence=geofence_for(mission),
                      separation=separation)


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


@dataclass
class Drone:
    """One vehicle of the lock-step fleet: its simulator and flight link, and what it flew."""

    name: str
    sim: Simulator
    link: FlightLink
    earth: LocalFrame  # where its map frame lies on the Earth
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))  # the map frame's origin in its world
    records: list[dict] = field(default_factory=list)  # its commands, as decisions.jsonl has them
    path: list[tuple[float, float]] = field(default_factory=list)  # where it was at each frame
    telemetry: list[tuple[float, Pose]] = field(default_factory=list)  # poses since the last frame, for depth
    camera_poses: dict[str, list[tuple[float, Pose]]] = field(default_factory=lambda: {"truth": [], "raw": []})
    separation: Separation | None = None  # a fleet's: what this drone's link hears of the others
    columns: ColumnLayers | None = None  # the newest layer set, decoded
    message: bytes | None = None  # ... and as it went over the wire
    frames: int = 0
    refused: Command | None = None  # a command refused for separation, sent again until it passes
    refused_at: float = 0.0  # mission time it was last refused


class LockstepMission:
    """The mission's vehicles flown in lock-step through one pipeline and one map, scored against the truth.

    Each vehicle has its own simulator (the same world; its sensors' errors seeded apart), flight link,
    depth service and pilot; each pilot keeps r_e away from the others' current targets and gives way to
    those listed before it, as the live decide nodes do. With one vehicle nothing of this shows."""

    def __init__(self, mission: Mission, progress_stream: TextIO | None = None, *, record_inputs: bool = False,
                 view=None, overlap: bool | None = None) -> None:
        """``view``: a ``viz.lockstep.LockstepView`` shown the first vehicle's run as it flies (None: no
        view, no rerun). ``overlap``: run the stages side by side (default: ``evaluation.overlap``).
        ``record_inputs``: keep the first vehicle's pilot inputs, for replay."""
        self.mission, self.vehicles = mission, tuple(mission.vehicles)
        self.vehicle = self.vehicles[0]
        self.view, self.record_inputs, self.progress_stream = view, record_inputs, progress_stream
        self.overlap = mission.evaluation.overlap if overlap is None else overlap
        # the run directory gets the map, not the mission's snapshot path
        mission = replace(mission, map_server=replace(mission.map_server, snapshot=""))
        self.pipeline = MissionPipeline(mission.core, vehicles=self.vehicles)
        self.pilot = self.pipeline.pilots[self.vehicle]
        self.truth, self.gt = GroundTruthDepth(), VoxelMap(mission.map_server.resolution)  # what the map is scored on
        home = mission.decide.home
        self.geometry = area_geometry(self.pilot.behavior.area, home, resolution=mission.map_server.resolution)
        self.aoi = zone_mask(self.pilot.behavior.area, self.geometry, home) > 0.5
        xmin, xmax, ymin, ymax = self.geometry.extent
        # aligned to the truth and absolute, with the offset
        self.scorer = MapScorer(self.geometry, self.aoi, np.array([xmin, ymin, -1000.0]),
                                np.array([xmax, ymax, 1000.0]))
        self.sampler = SeriesSampler(self.scorer.names, SAMPLE_INTERVAL)
        self.fleet = FleetTracker(self.geometry, self.aoi, self.vehicles, mission.link.separation)
        self._scores: deque[tuple[float, Future]] = deque()  # samples taken, being scored
        self.drones: list[Drone] = []
        self.inputs: list[PilotInput] = []
        self._now = 0.0  # the mission clock, for the fleet's separation

    @property
    def map(self) -> VoxelMap:
        return self.pipeline.map.map

    def run(self, run_dir: str | Path) -> MissionResult:
        """Fly, then write the run directory (report, metrics, plots, maps, decisions)."""
        wall0 = time.monotonic()
        out = Path(run_dir)
        out.mkdir(parents=True, exist_ok=True)
        if self.view is not None:
            self.view.start(self.pilot.behavior, self.mission.decide.home, self.geometry)
        ev = self.mission.evaluation
        sim_cfg = replace(self.mission.simulator, step_s=ev.step_s, urls=("tcp:127.0.0.1:0",))
        stages = Stages(("depth", "truth", "score"), self.overlap)
        with ExitStack() as stack:
            apart = len(self.vehicles) > 1 and self.mission.link.separation > 0
            for i, name in enumerate(self.vehicles):
                seed = None if i == 0 else sim_cfg.world.seed + SENSOR_SEED_STRIDE * i
                sim = stack.enter_context(Simulator(replace(sim_cfg, sensor_seed=seed)))
                host, port = sim.endpoint.addresses[0]
                separation = Separation(self.mission.link.separation, self.mission.link.separation_stale_s,
                                        clock=lambda: self._now) if apart else None
                link = flight_link(self.mission, f"tcp:{host}:{port}", separation)
                stack.callback(link.close)
                self.drones.append(Drone(name, sim, link, sim.endpoint.ekf_frame, separation=separation))
            try:
                t = self._fly(stages)
            finally:
                stages.close()
        return self._write(out, t, time.monotonic() - wall0)

    def _start(self, drone: Drone, index: int) -> None:
        """Take off over MAVLink, then stand at the drone's hover point at rest, errors and battery fresh:
        the mission clock's 0. A fleet's drones hover ``START_SPACING`` m apart along x."""
        sim, link, pilot = drone.sim, drone.link, self.pipeline.pilots[drone.name]
        altitude = pilot.behavior.altitude
        _take_off(sim, link, altitude, pilot.cruise_speed or None)
        drone.origin = np.asarray(sim.endpoint.ekf_origin, float)
        home = self.mission.decide.home
        hover = np.array([home[0] + START_SPACING * index, home[1], altitude])
        sim.endpoint.restart_errors()  # the mission's sensor errors must not depend on how long the take-off took
        link.set_waypoint(*hover, yaw=0.0)
        sim.endpoint.step(self.mission.evaluation.step_s)
        v = sim.vehicle
        v.position[:], v.velocity[:], v.acceleration[:], v.yaw, v.yaw_rate = hover + drone.origin, 0.0, 0.0, 0.0, 0.0
        sim.endpoint.battery.swap()  # full at the mission clock's 0: the wall-paced take-off must not count

    def _fly(self, stages: Stages) -> float:
        mission, ev = self.mission, self.mission.evaluation
        for i, drone in enumerate(self.drones):
            self._start(drone, i)
        steps = 0  # the mission clock is steps * step_s: exact, whatever the take-off took
        progress = Progress(ev.duration, f"{mission.decide.behavior} mission", "s", self.progress_stream)
        frame_period, layer_period = 1.0 / mission.sim.frame_rate_hz, 1.0 / mission.map_server.layers_rate
        next_frame = next_layers = t = 0.0
        fleet = len(self.drones) > 1
        while True:
            shots: list[tuple[Drone, np.ndarray, CameraFrame | None, CameraFrame | None]] = []
            frame_due = t >= next_frame - 1e-9
            if frame_due:
                next_frame += frame_period
            for drone in self.drones:
                reported = drone.sim.endpoint.reported_pose()  # what the autopilot says, as the link node publishes it
                position = reported.position - drone.origin  # in the map frame
                body = Pose.from_euler(reported.roll, reported.pitch, reported.yaw, position)
                self.pipeline.pose(drone.name, t, body)
                drone.telemetry.append((t, body))
                frame = reference = None
                if frame_due:  # rendered first: it needs only the pose, while the last frame's stereo runs
                    capture = drone.sim.capture(now=t)  # what the drone delivers; its truth is for scoring only
                    frame, reference = capture.frame.seen_from(drone.origin), capture.truth.seen_from(drone.origin)
                shots.append((drone, position, frame, reference))
            if fleet:
                self._now = t
                self.fleet.positions(t, {d.name: d.sim.vehicle.position - d.origin for d in self.drones})
                self._hear_each_other(shots)
            if t >= next_layers - 1e-9:  # the map's layer set, through the wire codec: every cloud so far is in
                next_layers += layer_period
                stages.settle("depth", "truth")
                for drone in self.drones:
                    self._layers(drone)
            for drone, position, _, _ in shots:
                self._pilot_step(drone, position, t, round(100 * drone.sim.endpoint.battery.remaining) / 100)
            for drone, position, frame, reference in shots:
                if frame is not None:
                    self._frame(drone, t, frame, reference, position, stages)
            if self.sampler.due(t):  # the maps as they are now; the scoring runs beside the flight
                stages.settle("depth", "truth")
                self.sampler.taken(t)
                self._scores.append((t, stages.submit("score", self._snapshot(t).scores)))
            self._record_scores()
            last = self.sampler.series.last() if len(self.sampler.series) else {}
            waypoints = sum(len(d.records) for d in self.drones)
            progress.update(t, f"mapped {last.get('percent_mapped', 0.0):5.1f}% waypoints {waypoints}")
            if t >= ev.duration - 1e-9 or all(self.pipeline.pilots[d.name].ending
                                              and self.pipeline.pilots[d.name].arrived(p) for d, p, _, _ in shots):
                break  # the duration, or every drone home after its pilot turned home (its flight is over)
            for drone in self.drones:
                drone.sim.endpoint.step(ev.step_s)
            steps += 1
            t = steps * ev.step_s
        stages.settle()
        self._record_scores(wait=True)
        if self.sampler.series.last()["t"] < t:
            self.sampler.series.append(t, self._snapshot(t).scores())
        waypoints = sum(len(d.records) for d in self.drones)
        progress.close(f"mapped {self.sampler.series.last()['percent_mapped']:.1f}% waypoints {waypoints}")
        return t

    def _layers(self, drone: Drone) -> None:
        view = self.pipeline.layers(drone.name)
        drone.message = wire.encode_columns(view.columns, view.stamp, drone.name, self.mission.map_server.layers,
                                            view.near)
        drone.columns = wire.to_column_layers(wire.decode_layer_set(drone.message))

    def _targets(self) -> dict[str, np.ndarray]:
        """Each drone's current target (x, y), as its decisions tell the others."""
        return {d.name: target[:2] for d in self.drones
                if (target := self.pipeline.pilots[d.name].target) is not None}

    def _hear_each_other(self, shots) -> None:
        """Each drone's link hears where the others are (as reported) and where they go (their targets)."""
        targets = self._targets()
        for drone in self.drones:
            for other, position, _, _ in shots:
                if other is not drone:
                    drone.separation.heard(other.name, position, targets.get(other.name))

    def _pilot_step(self, drone: Drone, position: np.ndarray, t: float, charge: float) -> None:
        """The pilot's tick; a command goes to the vehicle over MAVLink, through the link's geofence and a
        fleet's separation."""
        pilot, link = self.pipeline.pilots[drone.name], drone.link
        evaluations = pilot.evaluations
        avoid, yield_to = (fleet_targets(self.vehicles, drone.name, self._targets(), self.mission.decide.coordinate)
                           if len(self.drones) > 1 else ((), ()))
        command = self.pipeline.tick(drone.name, t, drone.columns, battery=charge, avoid=avoid, yield_to=yield_to)
        first = drone is self.drones[0]
        if first and self.record_inputs and pilot.evaluations != evaluations:
            self.inputs.append(PilotInput(t, tuple(float(c) for c in position), drone.message, command))
        if command is None:
            if drone.refused is not None and t - drone.refused_at >= WAYPOINT_REPEAT_S - 1e-9:
                self._send(drone, drone.refused, t)
            return
        record = command.record() if len(self.drones) == 1 else {"vehicle": drone.name, **command.record()}
        if (refusal := self._send(drone, command, t)) is not None:
            record["refused"] = refusal
        drone.records.append(record)
        if self.view is not None and first:  # with the tick's A0..A3 when the maker chose it
            self.view.decision(t, record, None if command.decision is None else pilot.maker.last_tick)

    def _send(self, drone: Drone, command: Command, t: float) -> str | None:
        """The command to the vehicle over MAVLink at mission time ``t``; why the link refused it, or None. As
        in the link node, a refused waypoint is counted and the vehicle keeps on; one refused for separation
        is sent again every ``WAYPOINT_REPEAT_S``, as the decide node repeats its waypoint."""
        link = drone.link
        try:
            link.set_waypoint(*command.position, yaw=command.yaw, separate=command.reason != "battery")
        except WaypointRefused as exc:
            if link.refused[exc.kind] == 1:
                _log.warning("waypoint refused by the link of %s: %s", drone.name, exc)
            drone.refused, drone.refused_at = (command if exc.kind == "separation" else None), t
            return str(exc)
        drone.refused = None
        return None

    def _frame(self, drone: Drone, t: float, frame: CameraFrame, reference: CameraFrame, position: np.ndarray,
               stages: Stages) -> None:
        """A camera frame: stereo and insertion on one lane, the ground-truth reference (the same exposure
        at the true pose, with the true depth) on the other."""
        drone.frames += 1
        drone.path.append((float(position[0]), float(position[1])))
        drone.camera_poses["truth"].append((frame.stamp, reference.pose))  # this exposure's truth, by its stamp
        drone.camera_poses["raw"].append((frame.stamp, frame.pose))
        if self.view is not None and drone is self.drones[0]:
            if self.view.reads_map(t):
                stages.settle("depth", "truth")
            self.view.frame(t, frame, position, self.map)
        elif self.view is not None:
            self.view.fleet_member(t, drone.name, position, self.pipeline.pilots[drone.name].target)
        max_range = self.mission.depth.max_depth
        poses, drone.telemetry = drone.telemetry, []
        fleet = len(self.drones) > 1

        def depth() -> None:
            for stamp, pose in poses:
                self.pipeline.telemetry(drone.name, stamp, pose)
            if (cloud := self.pipeline.frame(drone.name, frame)) is not None:
                self.pipeline.cloud(drone.name, cloud, max_range)
                if fleet:
                    self.fleet.saw(drone.name, cloud.points, t)

        def truth() -> None:
            if (cloud := self.truth.push(reference)) is not None and len(cloud):
                self.gt.insert(cloud.points, cloud.origin, cloud.colors, stamp=t)

        stages.submit("depth", depth)
        stages.submit("truth", truth)

    def _write(self, out: Path, t: float, wall_s: float) -> MissionResult:
        est, pilot, mission, lead = self.map, self.pilot, self.mission, self.drones[0]
        link, frame = lead.link, lead.earth
        position = self.pipeline.position(self.vehicle)
        est.save(out / "map.ot")
        for drone in self.drones:  # each pilot's state: `decide --resume` can go on from here
            name = "survey.json" if drone is lead else f"survey-{drone.name}.json"
            survey.save(self.pipeline.pilots[drone.name], out / name, t, t)
        est.export_bt(out / "map.bt")
        write_run_frame(out, frame)
        records = [r for d in self.drones for r in d.records]
        with open(out / "decisions.jsonl", "w") as f:
            for record in records:
                f.write(json.dumps(record, default=_json_default) + "\n")
        final_columns = est.column_layers_for(self.geometry)
        final_layers = compute_layers(final_columns, pilot.layer_context(final_columns, position, t),
                                      pilot.behavior.layer_names, est)
        images = dict(final_layers.layers)
        images["elevation_m"] = final_layers.elevation_m
        pilots = [self.pipeline.pilots[d.name] for d in self.drones]
        depths = [self.pipeline.depth[d.name] for d in self.drones]
        used = {"map_server.snapshot": str(out / "map.ot"), "decide.state": str(out / "survey.json"),
                "sim.urls": (link.config.url,), "sim.step_s": mission.evaluation.step_s,
                **{f"link.link.{k}": v for k, v in asdict(link.config).items()}}
        ended = [f"{p.ending}: {p.energy.why}" for p in pilots if p.ending]
        settings = {**to_settings(mission), **used, "waypoints": len(records), "reached": sum(p.reached for p in pilots),
                    "ended": f"{'; '.join(ended)}; home at t = {t:.1f} s" if ended else "duration",
                    "retargets": sum(r["reason"] == "retarget" for r in records),
                    "replans": sum(p.replans for p in pilots),  # a pattern's next flights over its gaps
                    "geofence": link.geofence.describe(),
                    "waypoints_refused": dict(sum((d.link.refused for d in self.drones), Counter())),
                    "frames": sum(d.frames for d in self.drones), "clouds": sum(s.clouds for s in depths),
                    **{f"depth_{k}": v for k, v in depths[0].stats().items()}}  # why frames gave no cloud
        if len(self.drones) > 1:
            settings.update({f"depth_{d.name}_{k}": v for d, s in zip(self.drones[1:], depths[1:])
                             for k, v in s.stats().items()})
        run = {"mission_s": round(t, 2), "wall_s": round(wall_s, 2),
               "real_time_factor": round(t / max(wall_s, 1e-9), 2)}
        extra = self._pose_errors(lead, depths[0].trajectory())
        if len(self.drones) > 1:  # work done twice while there was work to share: up to 90 % of the area
            t90 = time_to_percent(self.sampler.series, 90.0)
            extra.update(self.fleet.metrics(until=t if math.isnan(t90) else t90))
        path = (np.array(lead.path).reshape(-1, 2) if len(self.drones) == 1
                else {d.name: np.array(d.path).reshape(-1, 2) for d in self.drones})
        paths = write_run_report(out, f"layerpilot mission: {mission.decide.behavior}", self.sampler.series,
                                 final_columns, self.aoi, path, images, settings, extra, run)
        return MissionResult(out, {**self.sampler.series.last(), **extra}, len(records),
                             sum(d.frames for d in self.drones), sum(s.clouds for s in depths), wall_s, paths,
                             self.inputs)

    def _snapshot(self, t: float) -> MapSnapshot:
        """The maps to score, aligned by the common offset of the camera poses the first vehicle's clouds
        were placed with (a fleet's drones wander apart; the map is scored on its first drone's offset)."""
        lead = self.drones[0]
        placed = self.pipeline.depth[lead.name].trajectory()
        return self.scorer.snapshot(self.map, self.gt, t, (lead.camera_poses["truth"], placed))

    def _record_scores(self, wait: bool = False) -> None:
        """Append the finished samples to the series, in order (all of them with ``wait``)."""
        while self._scores and (wait or self._scores[0][1].done()):
            t, scores = self._scores.popleft()
            self.sampler.series.append(t, scores.result())
            if self.view is not None:
                self.view.metrics(t, self.sampler.series.last())

    def _pose_errors(self, drone: Drone, refined: list[tuple[float, Pose]]) -> dict[str, float]:
        """The camera poses as reported (``pose_raw_*``) and as the clouds were placed (``pose_refined_*``)
        against the truth, after the map's offset: median and p90 of position and attitude error."""
        truth, offset = drone.camera_poses["truth"], self.scorer.offset
        out: dict[str, float] = {}
        for name, estimate in (("raw", drone.camera_poses["raw"]), ("refined", refined)):
            if truth and estimate:
                out.update(pose_errors(truth, estimate, offset).as_dict(f"pose_{name}"))
        return out


def run_mission(mission: Mission, run_dir: str | Path, progress_stream: TextIO | None = None, *,
                record_inputs: bool = False, view=None, overlap: bool | None = None) -> MissionResult:
    """Fly the mission's vehicles in lock-step and write the run directory (see ``LockstepMission``)."""
    return LockstepMission(mission, progress_stream, record_inputs=record_inputs, view=view,
                           overlap=overlap).run(run_dir)
