"""Sensor profiles: the reported pose, the camera's stamps and its images carry the errors the profile states."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from layerpilot.config import ConfigError
from layerpilot.geometry import CameraFrame
from layerpilot.link.config import LinkConfig
from layerpilot.link.connection import open_connection
from layerpilot.link.frames import map_to_local_ned, yaw_enu_to_ned
from layerpilot.missionfile import load_mission
from layerpilot.camera import CameraConfig, camera_pose
from layerpilot.sim.camera_errors import CameraErrors, lens_maps
from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
from layerpilot.sim.pose_errors import PoseErrors
from layerpilot.sim.sensors import PROFILES, SensorProfile, sensor_profile
from layerpilot.sim.simulator import SimConfig, Simulator
from layerpilot.sim.vehicle import Multicopter

CONSUMER = PROFILES["consumer"]
SMALL = CameraConfig(width=320, height=240)


def error_series(profile: SensorProfile, chains: int = 200, seconds: float = 1800.0, dt: float = 5.0) -> dict:
    """Reported-minus-true errors of ``chains`` independent flights (seeds 0..chains-1), one row per flight
    (the processes are exact for any step)."""
    rows = {"east": [], "north": [], "up": [], "roll": [], "heading": [], "baro": []}
    for seed in range(chains):
        errors = PoseErrors(profile, np.random.default_rng([seed, 1]))
        series = [errors.step(dt) for _ in range(int(seconds / dt))]
        rows["east"].append([e.position[0] for e in series])
        rows["north"].append([e.position[1] for e in series])
        rows["up"].append([e.gnss[2] for e in series])
        rows["roll"].append([e.roll for e in series])
        rows["heading"].append([e.yaw for e in series])
        rows["baro"].append([e.drift[2] - e.gnss[2] for e in series])
    return {k: np.array(v) for k, v in rows.items()}


def correlation_time(x: np.ndarray, dt: float = 5.0) -> float:
    """tau of exp(-t / tau) from the autocovariances one and two steps apart (white noise drops out of the ratio)."""
    x = x - x.mean()
    c1 = np.mean(x[:, 1:] * x[:, :-1])
    c2 = np.mean(x[:, 2:] * x[:, :-2])
    return dt / math.log(c1 / c2)


@pytest.mark.parametrize("name, chains, rel_std, rel_tau", [("consumer", 200, 0.07, 0.15), ("rtk", 80, 0.1, 0.25),
                                                            ("degraded", 80, 0.1, 0.25)])
def test_pose_error_std_and_correlation_time_match_the_profile(name, chains, rel_std, rel_tau):
    """Up to 100 simulated hours (flights of 30 min): the EKF error's statistics are the profile's
    (consumer measured: 1.70/1.71 m, 126/124 s horizontal; 2.95 m, 120 s vertical; 0.50 deg, 30 s tilt)."""
    p = PROFILES[name]
    s = error_series(p, chains)
    horizontal = math.hypot(p.horizontal_sigma_m, p.horizontal_white_m)  # consumer: 1.703 m per axis
    for axis in ("east", "north"):
        assert s[axis].std() == pytest.approx(horizontal, rel=rel_std)
        assert correlation_time(s[axis]) == pytest.approx(p.horizontal_tau_s, rel=rel_tau)
    assert s["up"].std() == pytest.approx(p.vertical_sigma_m, rel=rel_std)
    assert correlation_time(s["up"]) == pytest.approx(p.vertical_tau_s, rel=rel_tau)
    assert np.degrees(s["roll"].std()) == pytest.approx(p.tilt_sigma_deg, rel=rel_std)
    assert correlation_time(s["roll"]) == pytest.approx(p.tilt_tau_s, rel=rel_tau)
    heading = np.degrees(s["heading"])
    assert heading.mean() == pytest.approx(p.heading_bias_deg, abs=0.15 * p.heading_sigma_deg)
    assert heading.std() == pytest.approx(p.heading_sigma_deg, rel=rel_std)
    assert correlation_time(s["heading"]) == pytest.approx(p.heading_tau_s, rel=rel_tau)
    # barometric height drifts linearly at the profile's rate, up or down as the seed has it
    final = s["baro"][:, -1]
    assert np.allclose(np.abs(final) / 1800.0 * 60.0, p.baro_drift_m_per_min)
    if p.baro_drift_m_per_min:
        assert 0.3 < np.mean(final > 0) < 0.7


def test_the_pose_error_moves_smoothly_between_reports():
    """Low-passed, as an EKF's outputs are: between 10 Hz reports the drift moves ~1 cm, not the 7 cm of a
    first-order process, and the heading 0.01 degrees, not 0.1; a second apart the heading error differs by
    about 0.17 degrees (first-order: 0.37), which is what lets the images' turns tell the camera's clock."""
    errors = PoseErrors(CONSUMER, np.random.default_rng([0, 1]))
    series = [errors.step(0.1) for _ in range(6000)]
    drift = np.array([e.drift[:2] for e in series])
    assert np.diff(drift, axis=0).std() < 0.03
    assert drift.std() > 0.5  # while it wanders by metres
    heading = np.degrees([e.yaw for e in series])
    assert np.diff(heading).std() < 0.03
    assert (heading[10:] - heading[:-10]).std() < 0.25
    assert heading.std() > 1.0  # while it wanders by degrees


def test_consumer_is_at_least_as_hard_as_an_m8_class_receiver():
    p = CONSUMER
    assert p.horizontal_sigma_m >= 1.5 and p.horizontal_tau_s >= 60.0 and p.horizontal_white_m > 0.0
    assert p.vertical_sigma_m >= 3.0 and p.baro_drift_m_per_min > 0.0
    assert p.tilt_sigma_deg >= 0.5 and math.hypot(p.heading_sigma_deg, p.heading_bias_deg) >= 2.0
    assert p.heading_bias_deg != 0.0
    assert p.clock_offset_s >= 0.08 and p.clock_jitter_s >= 0.01
    # rtk is better and degraded worse in every pose number
    for name in ("horizontal_sigma_m", "vertical_sigma_m", "tilt_sigma_deg", "heading_sigma_deg", "clock_offset_s"):
        assert getattr(PROFILES["rtk"], name) < getattr(p, name) < getattr(PROFILES["degraded"], name)


def test_same_seed_same_errors_other_seed_other_errors():
    a, b, c = (PoseErrors(CONSUMER, np.random.default_rng([seed, 1])) for seed in (3, 3, 4))
    ea, eb, ec = ([e.step(0.1).position for _ in range(50)] for e in (a, b, c))
    assert np.array_equal(ea, eb)
    assert not np.allclose(ea, ec)


def test_restarted_errors_do_not_depend_on_the_steps_before():
    """A lock-step mission restarts the errors at its clock's 0: a take-off of any length, the same errors after."""
    from layerpilot.sim.estimate import Estimator

    def state(errors: PoseErrors) -> np.ndarray:
        e = errors.current
        return np.array([*e.position, *e.drift, e.roll, e.pitch, e.yaw])

    def after_restart(steps_before: int) -> list[np.ndarray]:
        vehicle = MavlinkVehicle(Multicopter(position=(0.0, 0.0, 30.0)), "tcp:127.0.0.1:0",
                                 EndpointConfig(sensors=CONSUMER, seed=3))
        for _ in range(steps_before):
            vehicle.step(0.05)
        vehicle.restart_errors()
        errors = []
        for _ in range(40):
            vehicle.step(0.05)
            errors.append(state(vehicle.estimator.errors))
        return errors

    a = after_restart(7)
    assert np.array_equal(a, after_restart(300))
    fresh = Estimator(CONSUMER, 3)  # the same errors as a flight that starts with the mission's clock
    first = []
    for _ in range(40):
        fresh.errors.step(0.05)
        first.append(state(fresh.errors))
    assert np.array_equal(a, first)


def test_clock_offset_and_jitter_of_the_stamps():
    """stamp - exposure = -offset + N(0, jitter) - U(0, trigger): mean -110 ms, std 11.5 ms for consumer."""
    camera = CameraErrors(CONSUMER, SMALL.intrinsics, seed=0)
    d = np.array([camera.stamp_error() for _ in range(20000)])
    p = CONSUMER
    assert d.mean() == pytest.approx(-p.clock_offset_s - p.trigger_jitter_s / 2, abs=0.0005)
    assert d.std() == pytest.approx(math.sqrt(p.clock_jitter_s ** 2 + p.trigger_jitter_s ** 2 / 12), rel=0.03)
    assert d.max() < 0.0  # the camera's clock is behind: its stamps precede the exposure


def hovering_sim(profile: str, **overrides) -> Simulator:
    sim = Simulator(SimConfig(urls=("tcp:127.0.0.1:0",), camera=SMALL, sensors=profile, sensor_overrides=overrides))
    sim.vehicle.position[2] += 40.0
    sim.vehicle.motors_on = True
    sim.vehicle.hold()
    return sim


def test_perfect_frames_are_the_rendered_view_at_the_true_pose():
    with hovering_sim("perfect") as sim:
        assert sim.camera is None
        for _ in range(30):
            sim.endpoint.step(0.05)
        c = sim.capture()
        pose = sim.endpoint.pose()
        expected = sim.renderer.render_vehicle(pose.position, pose.yaw, pose.time)
        assert c.frame is c.truth
        assert np.array_equal(c.frame.image, expected.image) and np.array_equal(c.frame.depth, expected.depth)
        assert np.array_equal(c.frame.pose.matrix, expected.pose.matrix) and c.frame.stamp == pose.time
        reported = sim.endpoint.reported_pose()
        assert np.array_equal(reported.position, pose.position) and reported.yaw == pose.yaw


def test_a_frame_carries_the_reported_pose_at_its_camera_clock_stamp():
    """Exact EKF, clock 100 ms behind: a node looking the pose up at the stamp places a moving camera
    100 ms back along its track (1 m at 10 m/s), as on a real drone."""
    pose_exact = {k: 0.0 for k in ("horizontal_sigma_m", "horizontal_white_m", "vertical_sigma_m",
                                   "baro_drift_m_per_min", "tilt_sigma_deg", "heading_sigma_deg", "heading_bias_deg",
                                   "clock_jitter_s", "trigger_jitter_s")}
    with hovering_sim("consumer", **pose_exact) as sim:
        sim.vehicle.set_velocity_target(10.0, 0.0, 0.0)
        for _ in range(100):
            sim.endpoint.step(0.05)
        assert sim.vehicle.velocity[0] == pytest.approx(10.0)
        c = sim.capture()
        assert c.frame.stamp == pytest.approx(c.truth.stamp - 0.1)
        assert c.frame.pose.position - c.truth.pose.position == pytest.approx([-1.0, 0.0, 0.0], abs=1e-6)
        assert np.allclose(c.frame.pose.rotation, c.truth.pose.rotation)


def test_the_stepped_simulator_hands_out_the_delivered_frame():
    """What the sim node publishes (Simulator.step -> run): the camera-clock stamp and the reported pose."""
    with hovering_sim("consumer") as sim:
        shots = [shot for _ in range(60) if (shot := sim.step()) is not None]
        assert len(shots) == 7  # 5 Hz over 1.2 s: t = 0.02 (the first step), 0.2, ..., 1.2
        stamp, frame = shots[-1]
        assert stamp == frame.stamp and -0.14 < stamp - sim.time < -0.08  # 100 ms behind, jitter, trigger latency
        reported = sim.endpoint.reported_pose_at(stamp)
        assert frame.pose.position == pytest.approx(reported.position, abs=1e-9)


def test_consumer_frames_carry_the_ekf_error_and_the_truth_is_kept_apart():
    with hovering_sim("consumer") as sim:
        for _ in range(60):
            sim.endpoint.step(0.05)
        c = sim.capture()
        true = sim.endpoint.pose()
        reported = sim.endpoint.reported_pose()
        error = sim.endpoint.estimator.errors.current
        assert reported.position - true.position == pytest.approx(error.position)
        assert reported.yaw - true.yaw == pytest.approx(error.yaw)
        # hovering, the frame's pose is the reported one 0.11 s before (white noise 0.1 m and the wander of
        # 0.11 s apart), the truth's the true one
        assert c.frame.pose.position == pytest.approx(reported.position, abs=0.5)
        assert np.linalg.norm(c.frame.pose.position - c.truth.pose.position) > 1.0
        assert np.array_equal(c.truth.pose.position, true.position) and c.truth.depth is not None
        turn = np.degrees(np.arccos(np.clip((np.trace(c.frame.pose.rotation.T @ c.truth.pose.rotation) - 1) / 2,
                                            -1, 1)))
        tilt = math.degrees(math.sqrt(error.roll ** 2 + error.pitch ** 2 + error.yaw ** 2))
        assert turn == pytest.approx(tilt, rel=0.05)
        assert np.abs(c.frame.image.astype(int) - c.truth.image).mean() > 1.0


def test_a_mission_chooses_a_profile_and_overrides_fields(tmp_path):
    mission = load_mission("consumer")
    assert mission.sim.sensors == "consumer"
    assert mission.sim.sensor_profile.horizontal_sigma_m == CONSUMER.horizontal_sigma_m
    text = '[sim]\nsensors = "rtk"\n[sim.sensor_overrides]\nclock_offset_s = 0.2\njpeg_quality = 70\n'
    (tmp_path / "m.toml").write_text(text)
    profile = load_mission(tmp_path / "m.toml").sim.sensor_profile
    assert profile == dataclasses.replace(PROFILES["rtk"], clock_offset_s=0.2, jpeg_quality=70)
    for body, named in (('[sim.sensor_overrides]\nhorizontl_sigma_m = 2.0\n', "sim.sensor_overrides.horizontl_sigma_m"),
                        ('[sim]\nsensors = "cheap"\n', "sim.sensors"),
                        ('[sim.sensor_overrides]\njpeg_quality = 200\n', "sim.sensor_overrides.jpeg_quality"),
                        ('[sim.sensor_overrides]\njpeg_quality = 7.5\n', "sim.sensor_overrides.jpeg_quality")):
        (tmp_path / "bad.toml").write_text(body)
        with pytest.raises(ConfigError, match=named.replace(".", r"\.")):
            load_mission(tmp_path / "bad.toml")


def test_mavlink_position_and_attitude_messages_carry_the_error():
    """A pymavlink client on loopback reads what the EKF reports, not the truth (PX4 streams unasked)."""
    ground = 0.0
    endpoint = MavlinkVehicle(Multicopter(position=(0.0, 0.0, ground), ground_z=ground), "tcp:127.0.0.1:0",
                              EndpointConfig(flavour="px4", sensors=CONSUMER, seed=7))
    client = open_connection(f"tcp:127.0.0.1:{endpoint.addresses[0][1]}", 255, 190)
    try:
        got: dict[str, object] = {}
        for _ in range(200):
            endpoint.step(0.02)
            while (msg := client.recv_match(blocking=False)) is not None:
                got[msg.get_type()] = msg
        true, reported = endpoint.pose(), endpoint.reported_pose()
        assert np.linalg.norm(reported.position - true.position) > 0.5  # seed 7: metres off, as a consumer GNSS
        local = got["LOCAL_POSITION_NED"]
        # the last message was sent within the last 0.1 s; the error moves ~1 cm in that time (tau 120 s)
        assert [local.x, local.y, local.z] == pytest.approx(map_to_local_ned(*reported.position, endpoint.ekf_origin),
                                                            abs=0.3)
        assert abs(local.x - map_to_local_ned(*true.position, endpoint.ekf_origin)[0]) + \
            abs(local.y - map_to_local_ned(*true.position, endpoint.ekf_origin)[1]) > 0.5
        glob = got["GLOBAL_POSITION_INT"]
        lat, lon, alt = endpoint.config.origin.to_geodetic(*reported.position)
        assert glob.lat == pytest.approx(lat * 1e7, abs=30) and glob.lon == pytest.approx(lon * 1e7, abs=30)
        assert glob.alt == pytest.approx(alt * 1000, abs=300)
        attitude = got["ATTITUDE"]
        assert attitude.yaw == pytest.approx(yaw_enu_to_ned(reported.yaw), abs=1e-3)
        assert attitude.roll == pytest.approx(reported.roll, abs=1e-3)
        assert abs(attitude.yaw - yaw_enu_to_ned(true.yaw)) > math.radians(0.5)
    finally:
        client.close()
        endpoint.close()


def test_the_autopilot_flies_its_estimate_so_the_truth_is_off_by_the_error():
    """As a real autopilot: the link's waypoint is reached in the EKF's frame; the true vehicle is off by the error."""
    from layerpilot.link.link import FlightLink

    endpoint = MavlinkVehicle(Multicopter(position=(0.0, 0.0, 2.0), ground_z=2.0), "tcp:127.0.0.1:0",
                              EndpointConfig(sensors=CONSUMER, seed=3)).start(speed=10.0)
    config = LinkConfig(url=f"tcp:127.0.0.1:{endpoint.addresses[0][1]}", arrival_hold_s=0.3, arrival_tolerance_m=0.5,
                        command_timeout_s=1.0, ready_timeout_s=10.0)
    try:
        with FlightLink(config, clock=lambda: endpoint.time) as link:
            link.connect(5.0)
            link.wait_ready()
            link.start_guided()
            link.arm()
            link.takeoff(25.0)
            waypoint = np.array([40.0, 0.0, 25.0])
            link.goto(*waypoint)
            assert np.linalg.norm(link.telemetry().position - waypoint) <= 0.6  # arrived, as the EKF sees it
            with endpoint._lock:
                true = endpoint.pose().position - endpoint.ekf_origin
                drift = endpoint.estimator.errors.current.drift
            assert np.linalg.norm(true + drift - waypoint) < 0.7   # where its estimate is at the waypoint
            assert np.linalg.norm(true - waypoint) > 1.5           # seed 3: metres away in truth
    finally:
        endpoint.stop()


def textured(seed: int = 0) -> CameraFrame:
    """A 320x240 frame of smooth random texture 50 m in front of a camera looking down 60 degrees."""
    rng = np.random.default_rng(seed)
    image = cv2.resize(rng.integers(30, 220, (60, 80, 3)).astype(np.uint8), (320, 240), interpolation=cv2.INTER_CUBIC)
    depth = np.full((240, 320), 50.0, np.float32)
    return CameraFrame(image, camera_pose((0.0, 0.0, 40.0), 0.0, 60.0), SMALL.intrinsics, 0.0, depth)


def only(**fields) -> SensorProfile:
    return SensorProfile(**fields)


def sharpness(image: np.ndarray) -> float:
    return float(cv2.Laplacian(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float64), cv2.CV_64F).var())


def test_image_noise_has_the_profile_std():
    frame = textured()
    noisy = CameraErrors(only(noise_std=4.0), SMALL.intrinsics, 0).degrade(frame, np.zeros(3), 0.0)
    diff = noisy.astype(float) - frame.image
    assert diff.std() == pytest.approx(math.sqrt(4.0 ** 2 + 1 / 12), rel=0.03)  # plus rounding to whole numbers
    assert abs(diff.mean()) < 0.05


def test_motion_blur_follows_speed_and_exposure():
    """10 m/s sideways, 50 m away, 100 ms exposure: f v t / d = 160 px x 1 m / 50 m = 3.2 px of blur."""
    frame = textured()
    camera = CameraErrors(only(exposure_s=0.1), SMALL.intrinsics, 0)
    still = camera.degrade(frame, np.zeros(3), 0.0)
    moving = camera.degrade(frame, np.array([0.0, 10.0, 0.0]), 0.0)  # sideways: the image slides along u
    assert np.array_equal(still, frame.image)
    assert sharpness(moving) < 0.7 * sharpness(frame.image)
    # blurred along the motion (rows), not across it (columns)
    def gradient(image: np.ndarray, axis: int) -> float:
        return float(np.abs(np.diff(image.astype(float), axis=axis)).mean())

    du = gradient(moving, 1) / gradient(frame.image, 1)
    dv = gradient(moving, 0) / gradient(frame.image, 0)
    assert du < 0.85 and du < dv - 0.05  # measured 0.82 and 0.91


def test_jpeg_quality_sets_the_compression_error():
    frame = textured()
    errors = []
    for quality in (95, 60, 20):
        image = CameraErrors(only(jpeg_quality=quality), SMALL.intrinsics, 0).degrade(frame, np.zeros(3), 0.0)
        errors.append(np.abs(image.astype(float) - frame.image).mean())
    assert 0.0 < errors[0] < errors[1] < errors[2]


def test_exposure_changes_scale_brightness():
    frame = textured()
    camera = CameraErrors(only(exposure_sigma_ev=0.2), SMALL.intrinsics, 0)
    stops = [math.log2(camera.degrade(frame, np.zeros(3), 0.0).mean() / frame.image.mean()) for _ in range(200)]
    assert np.std(stops) == pytest.approx(0.2, rel=0.15)


def test_lens_distortion_with_a_slightly_wrong_calibration():
    k = SMALL.intrinsics
    u, v = np.meshgrid(np.arange(k.width, dtype=np.float32), np.arange(k.height, dtype=np.float32))
    exact_x, exact_y = lens_maps(k, only(k1=-0.05, k2=0.01))  # calibrated exactly: undistortion undoes the lens
    assert np.abs(exact_x - u).max() < 0.01 and np.abs(exact_y - v).max() < 0.01
    off_x, off_y = lens_maps(k, only(k1=-0.05, k2=0.01, calibration_error=0.02))
    shift = np.hypot(off_x - u, off_y - v)
    centre = shift[k.height // 2, k.width // 2]
    corner = shift[0, 0]
    radius = math.hypot(k.cx, k.cy)  # 200 px: a 2 % focal error alone moves the corner 4 px
    assert centre < 0.05 and 0.5 * 0.02 * radius < corner < 2.0 * 0.02 * radius
    image = CameraErrors(only(k1=-0.05, k2=0.01, calibration_error=0.02), k, 0).degrade(textured(), np.zeros(3), 0.0)
    assert np.abs(image.astype(int) - textured().image).mean() > 1.0


def test_unknown_profile_and_override_are_errors_naming_them():
    with pytest.raises(ConfigError, match="sensors: expected one of 'perfect', 'rtk', 'consumer', 'degraded'"):
        sensor_profile("consumr")
    with pytest.raises(ConfigError, match=r"sensor_overrides\.clock_offset_s = -1.0 is out of range"):
        sensor_profile("consumer", {"clock_offset_s": -1.0})
