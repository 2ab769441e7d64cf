"""One scored mission in one process, in lock-step: camera -> stereo -> map -> layers -> decision -> MAVLink -> vehicle.

The simulator's vehicle steps on the mission clock; waypoints reach it through the real
flight link (``FlightLink``) over MAVLink on a loopback TCP port. Everything the mission
decides from is a function of the seed: the camera pose and the decision position come
from the simulated vehicle's state, and waypoints carry an explicit yaw, so the link's
background re-sends are identical and change nothing.

The take-off (connect, pre-arm, GUIDED, arm, NAV_TAKEOFF, all over MAVLink) is paced by
the link's wall-clock waits and so is not part of the scored mission: when it is done the
vehicle is placed exactly at the hover point (0, 0, altitude) at rest, and the mission
clock starts at 0 there. That makes two runs with the same seed identical to the bit.
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from layerpilot.config import check_range
from layerpilot.eval.metrics import area_metrics, map_voxel_metrics
from layerpilot.eval.series import SAMPLE_INTERVAL, SeriesSampler
from layerpilot.eval.summary import write_run_report
from layerpilot.progress import Progress

BASELINES = ("lawnmower", "orbit")
METRICS = ["percent_mapped", "avg_time_since_observed", "avg_min_distance",
           "paper_recall", "paper_mse", "precision", "recall", "f_score"]


@dataclass(frozen=True)
class MissionConfig:
    """What to fly and how to simulate it; lengths in metres, times in mission seconds."""

    behavior: str = "balanced"  # a preset or .toml path, or a baseline: lawnmower, orbit
    duration: float = 600.0
    seed: int = 0  # decision noise
    world_seed: int = 0
    world_size: float = 400.0
    camera_width: int = 320
    camera_height: int = 240
    camera_pitch_deg: float = 60.0
    frame_rate_hz: float = 1.0
    step_s: float = 0.05
    map_resolution: float = 1.0
    arrival_radius: float = 3.0
    depth: str = "stereo"  # or "truth": the mission map from ground-truth depth too

    def __post_init__(self) -> None:
        check_range("duration", self.duration, 1.0, 36000.0)
        check_range("frame_rate_hz", self.frame_rate_hz, 0.05, 30.0)
        check_range("step_s", self.step_s, 0.005, 0.5)
        check_range("map_resolution", self.map_resolution, 0.1, 10.0)
        check_range("arrival_radius", self.arrival_radius, 0.5, 50.0)
        if self.depth not in ("stereo", "truth"):
            raise ValueError(f"depth: expected 'stereo' or 'truth', got {self.depth!r}")


@dataclass
class MissionResult:
    run_dir: Path
    final: dict[str, float]
    waypoints: int
    frames: int
    clouds: int
    wall_s: float
    report: dict[str, Path] = field(default_factory=dict)


class _Pilot:
    """Chooses the next waypoint: the MCDM decision maker, or a scripted baseline's list."""

    def __init__(self, cfg: MissionConfig, camera) -> None:
        from layerpilot.decide import DecisionMaker
        from layerpilot.decide.behavior import load_behavior

        # Baselines fly the balanced behavior's area and altitude.
        self.behavior = load_behavior("balanced" if cfg.behavior in BASELINES else cfg.behavior)
        self.area = self.behavior.area
        self.altitude = self.behavior.altitude
        self.script: np.ndarray | None = None  # (N, 4) x, y, z, yaw; flown in a loop
        self.cruise_speed: float | None = None  # m/s; None = the vehicle's top speed
        self._next = 0
        if cfg.behavior in BASELINES:
            from layerpilot.depth.config import PickConfig
            from layerpilot.sim import baselines

            radius = self.area.radius
            if cfg.behavior == "lawnmower":
                wps = baselines.lawnmower((0.0, 0.0), radius, self.altitude, camera, self.altitude)
                # straight legs at top speed put frames too far apart for stereo: fly at survey speed
                self.cruise_speed = baselines.survey_speed(camera, self.altitude, cfg.frame_rate_hz,
                                                           PickConfig().target_baseline_ratio)
            else:
                wps = baselines.orbit((0.0, 0.0), radius, self.altitude)
            self.script = wps
        self.maker = None if self.script is not None else DecisionMaker(self.behavior, (0.0, 0.0), seed=cfg.seed)

    def next(self, layers_fn, position: np.ndarray, t: float) -> tuple[np.ndarray, float, dict]:
        """(waypoint xyz, yaw, record); a script starts over when it is done, as a patrol would."""
        if self.script is not None:
            wp = self.script[self._next % len(self.script)]
            self._next += 1
            return wp[:3], float(wp[3]), {"time": t, "waypoint": wp[:3].tolist(), "scripted": True}
        decision = self.maker.decide(layers_fn(), position, t)
        wp = np.array(decision.waypoint, dtype=np.float64)
        yaw = math.atan2(wp[1] - position[1], wp[0] - position[0])
        return wp, yaw, {**decision.to_dict(), "explanation": decision.explain()}


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
            link.takeoff(altitude - float(sim.vehicle.ground_z))
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


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def run_mission(cfg: MissionConfig, run_dir: str | Path, progress_stream: TextIO | None = None) -> MissionResult:
    """Fly ``cfg`` and write the run directory (report, metrics, plots, maps, decisions)."""
    from layerpilot.decide import area_geometry, zone_mask
    from layerpilot.depth.simulated import to_frame
    from layerpilot.depth.source import GroundTruthDepth, StereoDepth
    from layerpilot.layers import LayerContext, compute_layers
    from layerpilot.link.config import LinkConfig
    from layerpilot.link.link import FlightLink
    from layerpilot.map import VoxelMap
    from layerpilot.sim import CameraConfig, WorldConfig
    from layerpilot.sim.simulator import SimConfig, Simulator

    wall0 = time.monotonic()
    out = Path(run_dir)
    out.mkdir(parents=True, exist_ok=True)
    camera = CameraConfig(width=cfg.camera_width, height=cfg.camera_height, pitch_deg=cfg.camera_pitch_deg)
    pilot = _Pilot(cfg, camera)
    home = (0.0, 0.0)
    geometry = area_geometry(pilot.area, home, resolution=cfg.map_resolution)
    aoi = zone_mask(pilot.area, geometry, home) > 0.5
    xmin, xmax, ymin, ymax = geometry.extent
    box_min, box_max = np.array([xmin, ymin, -1000.0]), np.array([xmax, ymax, 1000.0])
    est, gt = VoxelMap(cfg.map_resolution), VoxelMap(cfg.map_resolution)
    estimator = StereoDepth() if cfg.depth == "stereo" else GroundTruthDepth()
    truth = GroundTruthDepth()
    sampler = SeriesSampler(METRICS, SAMPLE_INTERVAL)
    sim_cfg = SimConfig(world=WorldConfig(seed=cfg.world_seed, size=cfg.world_size), camera=camera,
                        frame_rate_hz=cfg.frame_rate_hz, step_s=cfg.step_s, urls=("tcp:127.0.0.1:0",))
    frames = clouds = 0
    path: list[tuple[float, float]] = []
    records: list[dict] = []
    with Simulator(sim_cfg) as sim:
        host, port = sim.endpoint.addresses[0]
        # Heartbeats come at 1 Hz of mission time; a slow lock-step frame must not look like a lost link.
        link = FlightLink(LinkConfig(url=f"tcp:{host}:{port}", heartbeat_timeout_s=600.0))
        try:
            _take_off(sim, link, pilot.altitude, pilot.cruise_speed)
            hover = np.array([0.0, 0.0, pilot.altitude])
            link.set_waypoint(*hover, yaw=0.0)
            sim.endpoint.step(cfg.step_s)
            v = sim.vehicle
            v.position[:], v.velocity[:], v.acceleration[:], v.yaw, v.yaw_rate = hover, 0.0, 0.0, 0.0, 0.0
            steps = 0  # the mission clock is steps * step_s: exact, whatever the take-off took
            progress = Progress(cfg.duration, f"{cfg.behavior} mission", "s", progress_stream)
            target: np.ndarray | None = None
            next_frame, t = 0.0, 0.0

            def layer_set(now: float, position: np.ndarray):
                ctx = LayerContext(now=now, home=home, position=tuple(position), options=pilot.behavior.layers)
                return compute_layers(est.column_layers_for(geometry), ctx, pilot.behavior.layer_names, est)

            def metrics(now: float) -> dict[str, float]:
                area = area_metrics(est.column_layers_for(geometry), aoi, now)
                return {**area.as_dict(), **map_voxel_metrics(est, gt, box_min, box_max).as_dict()}

            while True:
                position = sim.endpoint.pose().position.copy()
                if target is None or np.linalg.norm(position - target) <= cfg.arrival_radius:
                    target, yaw, record = pilot.next(lambda: layer_set(t, position), position, t)
                    link.set_waypoint(*target, yaw=yaw)
                    records.append(record)
                if t >= next_frame - 1e-9:
                    next_frame += 1.0 / cfg.frame_rate_hz
                    pose = sim.endpoint.pose()
                    frame = to_frame(sim.renderer.render_vehicle(pose.position, pose.yaw), t)
                    frames += 1
                    path.append((float(pose.position[0]), float(pose.position[1])))
                    for source, voxels in ((estimator, est), (truth, gt)):
                        cloud = source.push(frame)
                        if cloud is not None and len(cloud):
                            voxels.insert(cloud.points, cloud.origin, cloud.colors, stamp=t)
                            clouds += voxels is est
                sampler.maybe_sample(t, lambda: metrics(t))
                last = sampler.series.last() if len(sampler.series) else {}
                progress.update(t, f"mapped {last.get('percent_mapped', 0.0):5.1f}% waypoints {len(records)}")
                if t >= cfg.duration - 1e-9:
                    break
                sim.endpoint.step(cfg.step_s)
                steps += 1
                t = steps * cfg.step_s
            if sampler.series.last()["t"] < t:
                sampler.series.append(t, metrics(t))
            progress.close(f"mapped {sampler.series.last()['percent_mapped']:.1f}% waypoints {len(records)}")
        finally:
            link.close()

    est.save(out / "map.ot")
    est.export_bt(out / "map.bt")
    with open(out / "decisions.jsonl", "w") as f:
        for record in records:
            f.write(json.dumps(record, default=_json_default) + "\n")
    final_layers = compute_layers(
        est.column_layers_for(geometry),
        LayerContext(now=t, home=home, options=pilot.behavior.layers),
        pilot.behavior.layer_names,
        est,
    )
    images = dict(final_layers.layers)
    images["elevation_m"] = final_layers.elevation_m
    settings = {**asdict(cfg), "waypoints": len(records), "frames": frames, "clouds": clouds,
                **{f"depth_{k}": v for k, v in estimator.stats().items()},  # why frames gave no cloud
                "wall_s": round(time.monotonic() - wall0, 1)}
    paths = write_run_report(out, f"layerpilot mission: {cfg.behavior}", sampler.series,
                             est.column_layers_for(geometry), aoi, np.array(path).reshape(-1, 2), images, settings)
    return MissionResult(out, sampler.series.last(), len(records), frames, clouds,
                         time.monotonic() - wall0, paths)
