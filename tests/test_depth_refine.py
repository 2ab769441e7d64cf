"""Live pose refinement on rendered frames with known errors: a perturbed pair is put back, a pair whose
images contradict its priors is rejected and counted, and the camera clock's offset is learnt."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from layerpilot.depth.config import preset_for
from layerpilot.depth.evaluate import score
from layerpilot.depth.live import LiveConfig, LiveRefiner
from layerpilot.depth.stereo import StereoMatcher
from layerpilot.eval.fixtures import PairSpec, render_pair, sideways_flight
from layerpilot.geometry import CameraFrame, Pose
from layerpilot.mission.depth_service import DepthService, DepthServiceConfig
from layerpilot.camera import CameraConfig
from layerpilot.sim import Renderer, World, WorldConfig
from layerpilot.sim.pose_errors import PoseErrors
from layerpilot.sim.sensors import PROFILES
from layerpilot.camera import camera_pose

from conftest import wait_for

SIZE = (320, 240)


@pytest.fixture(scope="module")
def world() -> World:
    return World(WorldConfig())


@pytest.fixture(scope="module")
def pair(world) -> tuple[CameraFrame, CameraFrame]:
    with Renderer(world, CameraConfig(width=SIZE[0], height=SIZE[1], pitch_deg=60.0)) as r:
        return render_pair(r, PairSpec(-70, 50, 40, 60, 45, ratio=0.09), stamp=1.0)


def _turned(frame: CameraFrame, rotvec_deg, shift) -> CameraFrame:
    R = Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix() @ frame.pose.rotation
    return dataclasses.replace(frame, pose=Pose.from_rotation(R, frame.pose.position + np.asarray(shift, float)))


def _precision(ref: CameraFrame, partner: CameraFrame, truth: CameraFrame) -> float:
    config = preset_for(SIZE[0])
    cloud, _ = StereoMatcher(config.match).cloud(ref, partner)
    return score(cloud, truth, scale=config.match.scale).precision


def test_refinement_recovers_a_known_perturbation_of_a_rendered_pair(pair):
    ref, partner = pair
    # the partner reported 1.2 degrees turned and 0.15 m off across the baseline (a consumer fix's own noise;
    # the slowly wandering part of GNSS's error is common to both fixes): a degree is 0.7 m at 40 m
    wrong = _turned(partner, [0.7, -0.6, 0.8], 0.15 * ref.pose.rotation[:, 1])
    assert _precision(ref, wrong, ref) < 0.5  # the raw poses ruin the pair
    refiner = LiveRefiner()
    out = refiner.refine(ref, wrong)
    assert out is not None and refiner.stats()["refined"] == 1
    new_ref, new_partner = out
    # the relative pose is the images': rotation within 0.15 degrees (0.1 measured), baseline direction within 0.5 (0.22)
    true_rel = partner.pose.rotation.T @ ref.pose.rotation
    got_rel = new_partner.pose.rotation.T @ new_ref.pose.rotation
    assert math.degrees(Rotation.from_matrix(true_rel.T @ got_rel).magnitude()) < 0.15
    true_b = partner.pose.to_local(ref.pose.position[None])[0]
    got_b = new_partner.pose.to_local(new_ref.pose.position[None])[0]
    cos = true_b @ got_b / np.linalg.norm(true_b) / np.linalg.norm(got_b)
    assert math.degrees(math.acos(min(1.0, cos))) < 0.5
    # ... and the stereo pair is good again, scored against the true depth of the reference view
    assert _precision(new_ref, new_partner, ref) > 0.9


def test_a_pair_whose_images_contradict_its_priors_is_rejected_and_counted(pair):
    ref, partner = pair
    refiner = LiveRefiner()
    assert refiner.refine(ref, _turned(partner, [0.0, 0.0, 12.0], [0.0, 0.0, 0.0])) is None
    assert refiner.refine(ref, _turned(partner, [0.0, 0.0, 0.0], 4.0 * ref.pose.rotation[:, 2])) is None
    blank = dataclasses.replace(partner, image=np.full_like(partner.image, 128))
    assert refiner.refine(ref, blank) is None
    stats = refiner.stats()
    assert stats["refined"] == 0
    assert stats["rejected_rotation_disagrees"] == 1
    assert stats["rejected_direction_disagrees"] == 1
    assert stats["rejected_too_few_matches"] == 1
    assert refiner.trajectory() == []


def _weaving_flight(t: np.ndarray, start=(-60.0, 40.0), speed: float = 5.0, amplitude_deg: float = 15.0,
                    period: float = 7.0) -> tuple[np.ndarray, np.ndarray]:
    """Positions (N, 2) and headings (N,) of a flight that weaves left and right of east at ``speed``."""
    heading = np.radians(amplitude_deg) * np.sin(2 * np.pi * t / period)
    dt = np.diff(t, prepend=t[0])
    xy = np.asarray(start) + np.cumsum(speed * dt[:, None] * np.column_stack([np.cos(heading), np.sin(heading)]), 0)
    return xy, heading


def _offset_flight(world, offset: float, frames: int = 24, rate: float = 20.0, lead: float = 1.0,
                   sensors: str = "perfect"):
    """Events of the weaving flight with a camera clock ``offset`` seconds behind the telemetry:
    ("pose", stamp, body pose) at ``rate`` Hz, running ``lead`` seconds ahead of ("frame", CameraFrame)
    at 1 Hz, each frame stamped on the camera's clock and carrying the telemetry's pose at that stamp.
    The telemetry's heading carries the ``sensors`` profile's heading error (the frames' poses do not)."""
    t = np.arange(0.0, frames + 2.0, 1.0 / rate)
    xy, heading = _weaving_flight(t)
    altitude = float(world.terrain_height(*xy[0])) + 45.0
    errors = PoseErrors(PROFILES[sensors], np.random.default_rng(0))
    reported = heading + np.array([errors.step(1.0 / rate).yaw for _ in t])
    body = [Pose.from_euler(0.0, 0.0, float(h), (x, y, altitude)) for (x, y), h in zip(xy, reported)]
    sent = 0
    with Renderer(world, CameraConfig(width=SIZE[0], height=SIZE[1], pitch_deg=60.0)) as r:
        for k in range(1, frames):
            exposure = float(k)  # on the telemetry's clock
            while sent < len(t) and t[sent] <= exposure + lead:
                yield "pose", float(t[sent]), body[sent]
                sent += 1
            i = int(round(exposure * rate))
            truth = r.render(camera_pose((*xy[i], altitude), float(heading[i]) + math.pi / 2, 60.0), exposure)
            stamp = exposure - offset  # the camera's clock
            j = stamp * rate  # the reported pose: the telemetry at the camera's stamp
            lo = int(math.floor(j))
            s = j - lo
            pos = (1 - s) * np.array([*xy[lo], altitude]) + s * np.array([*xy[lo + 1], altitude])
            yaw = (1 - s) * heading[lo] + s * heading[lo + 1]
            yield "frame", dataclasses.replace(truth, pose=camera_pose(pos, float(yaw) + math.pi / 2, 60.0), stamp=stamp)


@pytest.mark.parametrize("offset, sensors", [(0.12, "perfect"), (0.25, "degraded")])
def test_time_offset_estimate_converges_to_the_simulated_offset(world, offset, sensors):
    """Frames stamped behind the telemetry, their reported poses read at the wrong time: the service learns
    the offset from how the camera turned, within 20 ms, also through the degraded profile's heading error."""
    service = DepthService(DepthServiceConfig())
    for kind, *event in _offset_flight(world, offset, sensors=sensors):
        if kind == "pose":
            service.push_pose(*event)
        else:
            service.push(event[0])
    stats = service.stats()
    assert stats["refined"] >= 15, stats
    assert stats["time_offset_pairs"] >= 5, stats
    assert stats["time_offset_s"] == pytest.approx(offset, abs=0.02), stats
    trajectory = service.trajectory()
    assert len(trajectory) >= 15 and all(s2 > s1 for (s1, _), (s2, _) in zip(trajectory, trajectory[1:]))


def test_a_frame_the_telemetry_has_not_yet_reached_is_placed_on_the_telemetry_clock(world):
    """The telemetry arrives 50 ms behind the frames' exposures: once the offset is known, a frame is
    still placed at its exposure (the stream's last velocity carried on), not at its camera stamp (0.6 m
    back at 5 m/s), so the two frames of a pair are never placed on different clocks."""
    offset = 0.12
    service = DepthService(DepthServiceConfig())
    for kind, *event in _offset_flight(world, offset, lead=-0.05):
        service.push_pose(*event) if kind == "pose" else service.push(event[0])
    assert service.stats()["time_offset_s"] == pytest.approx(offset, abs=0.02)
    t = np.arange(0.0, 26.0, 1.0 / 20.0)
    xy, _ = _weaving_flight(t)
    keyframes = list(service.refiner.window.frames.values())
    assert len(keyframes) >= 8
    errors = [np.linalg.norm(k.prior.position[:2] - xy[int(round((k.stamp + offset) * 20.0))]) for k in keyframes]
    assert max(errors) < 0.15, errors  # the raw stamp's pose would be 0.6 m off


def test_the_depth_node_hears_the_pose_stream_and_reports_the_refinement(world):
    """Over the bus (loopback): the node's status carries pairs refined, rejections and the clock offset."""
    from layerpilot.bus.keys import Keys
    from layerpilot.bus.messages import FrameMessage, State, encode_frame, encode_state
    from layerpilot.bus.session import BusConfig, free_endpoint, open_session
    from layerpilot.missionfile import Mission
    from layerpilot.nodes.depth import DepthNode

    ep = free_endpoint()
    node_session, client = open_session(BusConfig(endpoint=ep)), open_session(BusConfig(endpoint=ep))
    node = DepthNode(node_session, "uav1", Mission())
    node.start()
    keys = Keys("uav1")
    poses, camera = client.declare_publisher(keys.pose), client.declare_publisher(keys.camera)
    try:
        wait_for(lambda: poses.matching_status.matching and camera.matching_status.matching,  # a put before it is lost
                 "the node's subscriptions", timeout=30.0)
        seq = 0
        for kind, *event in _offset_flight(world, 0.12):
            if kind == "pose":
                poses.put(encode_state(State(event[0], "uav1", event[1])))
                continue
            seq += 1
            time.sleep(0.05)  # the poses before the frame arrive first
            camera.put(encode_frame(FrameMessage("uav1", seq, event[0])))
            wait_for(lambda: node.status().get("frames", 0) >= seq, f"frame {seq} to be handled", timeout=30.0)
            assert node.status()["frames"] == seq, node.status()
        status = node.status()
    finally:
        node.stop()
        client.close()
        node_session.close()
    assert status["frames"] == seq and status["refined"] >= 15, status
    assert status["time_offset_s"] == pytest.approx(0.12, abs=0.02), status
    assert node.rejects.total == 0


def test_without_refinement_the_reported_poses_are_used_and_counted_as_such(pair):
    ref, partner = pair
    service = DepthService(DepthServiceConfig(refine=False))
    service.push(partner)
    service.push(ref)
    assert "refined" not in service.stats()
    assert [s for s, _ in service.trajectory()] == [partner.stamp, ref.stamp]


def test_refinement_settings_are_validated():
    from layerpilot.config import ConfigError

    for bad in (dict(window=1), dict(gnss_sigma_h=0.0), dict(max_clock_offset=-0.1), dict(yaw_sigma_deg=500.0)):
        with pytest.raises((ConfigError, ValueError), match="depth\\."):
            DepthServiceConfig(**bad)


def test_the_window_takes_a_heading_bias_out_with_the_gnss_track(world):
    """A 3 deg heading bias is the same in every reported pose, so no pair can see it; over 20 frames
    the images' trajectory against the GNSS track does."""
    rng = np.random.default_rng(3)
    with Renderer(world, CameraConfig(width=SIZE[0], height=SIZE[1], pitch_deg=60.0)) as r:
        frames = sideways_flight(r, (-60.0, 70.0), heading_deg=20.0, altitude=45.0, pitch_deg=60.0, speed=5.0,
                                 frames=20, period=1.0)
    offset = np.array([1.5, -1.0, 2.0])  # GNSS's slowly wandering error is a common offset over 20 s
    reported = [_turned(f, [0.0, 0.0, 3.0], offset + rng.normal(0.0, 0.1, 3)) for f in frames]
    service = DepthService(DepthServiceConfig())
    for f in reported:
        service.push(f)
    trajectory = service.trajectory()
    assert len(trajectory) >= 15
    truth = {f.stamp: f.pose for f in frames}

    def heading_error_deg(pose: Pose, stamp: float) -> float:
        R = pose.rotation @ truth[stamp].rotation.T
        return abs(math.degrees(math.atan2(R[1, 0], R[0, 0])))

    raw = np.median([heading_error_deg(f.pose, f.stamp) for f in reported])
    refined = np.median([heading_error_deg(p, s) for s, p in trajectory])
    assert raw == pytest.approx(3.0, abs=0.01)
    assert refined < 1.0, refined  # 0.59 measured


def test_a_window_adjustment_that_diverges_leaves_the_estimates_alone(pair):
    from layerpilot.depth.refine import Relative
    from layerpilot.depth.window import Edge, SlidingWindow

    ref, partner = pair
    window = SlidingWindow()
    a, b = window.keyframe(partner.stamp, partner.pose), window.keyframe(ref.stamp, ref.pose)
    bad = Relative(np.eye(3), np.array([np.nan, 0.0, 0.0]), np.zeros((0, 2), np.float32), np.zeros((0, 2), np.float32),
                   np.zeros(0, int), 0)
    assert not window.add(Edge(ref.stamp, partner.stamp, bad, math.nan))
    assert window.edges == [] and a.pose is partner.pose and b.pose is ref.pose


def test_the_smallest_window_keeps_a_pair_whose_partner_is_its_oldest_keyframe(world):
    """Window of 2: pairs (1, 0), (2, 1), then (3, 1) - the partner is the oldest keyframe left."""
    from layerpilot.depth.window import WindowConfig

    with Renderer(world, CameraConfig(width=SIZE[0], height=SIZE[1], pitch_deg=60.0)) as r:
        frames = sideways_flight(r, (-60.0, 70.0), heading_deg=20.0, altitude=45.0, pitch_deg=60.0, speed=2.5,
                                 frames=4, period=1.0)
    refiner = LiveRefiner(dataclasses.replace(LiveConfig(), window=WindowConfig(size=2)))
    for i, j in ((1, 0), (2, 1), (3, 1)):
        assert refiner.refine(frames[i], frames[j]) is not None
        assert sorted(refiner.window.frames) == sorted({frames[i].stamp, frames[j].stamp})
    assert refiner.stats()["refined"] == 3


def test_the_window_keeps_the_gnss_displacement_where_the_absolute_fix_wanders(world):
    """GNSS's error wanders slowly (here 3 m over 20 s on top of a common offset) but two fixes a second
    apart share it: the window's baselines then come out within a few per cent of the truth, and its worst
    ones far better than the same window's told to ignore the displacements (sigma 1 km)."""
    rng = np.random.default_rng(5)
    with Renderer(world, CameraConfig(width=SIZE[0], height=SIZE[1], pitch_deg=60.0)) as r:
        frames = sideways_flight(r, (-60.0, 70.0), heading_deg=20.0, altitude=45.0, pitch_deg=60.0, speed=5.0,
                                 frames=20, period=1.0)
    ramp = np.array([0.1, -0.08, 0.15])  # m/s of wander
    reported = [_turned(f, [0.0, 0.0, 0.0], [1.5, -1.0, 2.0] + ramp * k + rng.normal(0.0, 0.05, 3))
                for k, f in enumerate(frames)]
    truth = {f.stamp: f.pose.position for f in frames}

    def baseline_errors(config: DepthServiceConfig) -> np.ndarray:
        service = DepthService(config)
        for f in reported:
            service.push(f)
        placed = service.trajectory()
        assert len(placed) >= 15
        return np.array([abs(np.linalg.norm(b.position - a.position) / np.linalg.norm(truth[t] - truth[s]) - 1)
                         for (s, a), (t, b) in zip(placed, placed[1:])])

    kept = baseline_errors(DepthServiceConfig())
    ignored = baseline_errors(DepthServiceConfig(gnss_delta_sigma_h=1000.0, gnss_delta_sigma_v=1000.0))
    assert np.median(kept) < 0.03, np.median(kept)  # 0.024 measured (0.036 ignored)
    assert np.percentile(kept, 90) < 0.045, np.percentile(kept, 90)  # 0.036 (0.067 ignored)
    assert ignored.max() > 1.8 * kept.max(), (ignored.max(), kept.max())  # 0.150 against 0.061
