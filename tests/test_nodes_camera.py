"""The camera node: a video file rendered along a known flight + the recorded pose stream (with a gap)
on real Zenoh -> posed frames the depth service turns into a cloud; interpolation; reconnects."""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from layerpilot.bus import keys
from layerpilot.bus.messages import State, decode_frame, encode_state
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.config import ConfigError
from layerpilot.geometry import Pose
from layerpilot.mission.camera_track import CameraSettings, ClockOffset, PoseTrack, slerp
from layerpilot.mission.depth_service import DepthService, DepthServiceConfig
from layerpilot.nodes.camera import CameraNode
from layerpilot.camera import CameraConfig, camera_pose
from layerpilot.sim import Renderer, World, WorldConfig

from conftest import cli_process, wait_for

WORLD = WorldConfig(seed=11, size=120.0, trees_per_hectare=300.0, clearings=2, tile_size=30.0)
CAMERA = CameraConfig(width=320, height=240, hfov_deg=80.0, pitch_deg=70.0)
POSE_RATE, FPS, FILE_START, FRAMES = 10.0, 5.0, 9.85, 28
POSE_TIMES = [round(10.0 + i / POSE_RATE, 3) for i in range(51)]  # 10.0 .. 15.0 s
GAP = (12.5, 13.5)  # no poses in between: 1 s > max_gap
POSE_TIMES = [t for t in POSE_TIMES if not GAP[0] < t < GAP[1]]
OFFSET = [0.3, 0.1, -0.2]  # m, body FLU


def body(t: float) -> Pose:
    """The true flight: east at 4 m/s, 30 m up, turning at 0.1 rad/s, a little roll the gimbal takes out."""
    return Pose.from_euler(0.04, -0.03, 0.1 * (t - 10.0), (-20.0 + 4.0 * (t - 10.0), -5.0, 30.0))


def true_camera(t: float) -> Pose:
    b = body(t)
    yaw = b.yaw
    rz = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    return camera_pose(b.position + rz @ OFFSET, yaw, CAMERA.pitch_deg)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """A video file (MJPG) rendered along the flight, its calibration file, and the rendered frames."""
    out = tmp_path_factory.mktemp("camera")
    world = World(WORLD)
    renderer = Renderer(world, CAMERA)
    try:
        frames = [renderer.render(true_camera(FILE_START + i / FPS), FILE_START + i / FPS) for i in range(FRAMES)]
    finally:
        renderer.close()
    video = out / "flight.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (CAMERA.width, CAMERA.height))
    for f in frames:
        writer.write(cv2.cvtColor(f.image, cv2.COLOR_RGB2BGR))
    writer.release()
    calibration = out / "camera.yaml"
    fs = cv2.FileStorage(str(calibration), cv2.FILE_STORAGE_WRITE)
    fs.write("camera_matrix", CAMERA.intrinsics.K)
    fs.write("distortion_coefficients", np.zeros((1, 5)))
    fs.write("image_width", CAMERA.width)
    fs.write("image_height", CAMERA.height)
    fs.release()
    return video, calibration, {round(f.stamp, 6): f for f in frames}


def send_poses(session, key: str) -> None:
    """The recorded pose stream (with its gap), as the link node stamps it, once a subscriber listens."""
    publisher = session.declare_publisher(key)
    try:
        wait_for(lambda: publisher.matching_status.matching, "a subscriber of the pose key")
        for t in POSE_TIMES:
            publisher.put(encode_state(State(t, "uav1", body(t), armed=True, mode="GUIDED")))
    finally:
        publisher.undeclare()


def settings(video, calibration, **changes) -> CameraSettings:
    return CameraSettings(source=str(video), calibration=str(calibration), pitch_deg=CAMERA.pitch_deg,
                          offset=OFFSET, max_gap=0.5, file_start=FILE_START, **changes)



def wait_for_frames(got: list, node) -> None:
    """Camera frames are a lossy topic (Zenoh may drop under load): wait until every published frame
    arrived or what arrives stops growing."""
    seen = [-1]

    def settled() -> bool:
        settled_now, seen[0] = len(got) == seen[0], len(got)
        return settled_now or len(got) == node.published

    wait_for(lambda: time.sleep(0.3) or settled(), "the published frames to arrive")

def test_video_file_frames_get_interpolated_poses_gaps_are_dropped_and_depth_makes_a_cloud(flight):
    video, calibration, rendered = flight
    ep = free_endpoint()
    node_session, test_session = open_session(BusConfig(endpoint=ep)), open_session(BusConfig(endpoint=ep))
    k = keys.Keys("uav1")
    got = []
    sub = test_session.declare_subscriber(k.camera, lambda s: got.append(decode_frame(s.payload.to_bytes())))
    node = CameraNode(node_session, "uav1", settings(video, calibration))
    try:
        node.start()
        send_poses(test_session, k.pose)
        wait_for(lambda: len(node.track) == len(POSE_TIMES), "the recorded poses to arrive")
        node.run(threading.Event())  # returns at the file's end
        wait_for_frames(got, node)
    finally:
        sub.undeclare()
        node.stop()
        node_session.close()
        test_session.close()

    assert node.read == FRAMES
    # frame 0 (9.85 s) is before the first pose; 12.65 .. 13.45 s lie in the gap; 15.05 and 15.25 after the last
    assert dict(node.track.dropped) == {"before the first pose": 1, "telemetry gap": 5, "after the newest pose": 2}
    assert node.published == FRAMES - 8
    assert node.status()["dropped"] == dict(node.track.dropped)
    stamps = [m.frame.stamp for m in got]
    expected = [FILE_START + i / FPS for i in range(FRAMES)]
    expected = [t for t in expected if POSE_TIMES[0] <= t <= POSE_TIMES[-1] and not GAP[0] < t < GAP[1]]
    assert len(expected) == node.published
    # the camera topic is lossy: under load Zenoh may drop a frame on the way, never invent or reorder one
    assert node.published // 2 <= len(got) <= node.published
    assert [m.seq for m in got] == sorted({m.seq for m in got})
    assert all(min(abs(s - t) for t in expected) < 1e-9 for s in stamps), stamps
    for m in got:
        truth = true_camera(m.frame.stamp)  # mount offset and pitch applied, roll and pitch of the body not
        assert np.abs(m.frame.pose.position - truth.position).max() < 1e-6
        assert np.abs(m.frame.pose.rotation - truth.rotation).max() < 1e-6
        assert m.frame.intrinsics == CAMERA.intrinsics
        image = rendered[round(m.frame.stamp, 6)].image  # the file's frame, through MJPG
        assert np.abs(m.frame.image.astype(int) - image).mean() < 6.0

    service = DepthService(DepthServiceConfig())  # the depth node's step object takes them unchanged
    clouds = [(m.frame, c) for m in got if (c := service.push(m.frame)) is not None]
    assert clouds, f"no cloud from {len(got)} frames"
    frame, cloud = clouds[0]
    uv, z = frame.project(cloud.points)  # stereo depth against the renderer's depth of the same pixels
    inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < CAMERA.width - 0.5) & (uv[:, 1] >= 0) & (uv[:, 1] < CAMERA.height - 0.5)
    truth = rendered[round(frame.stamp, 6)].depth[np.round(uv[inside, 1]).astype(int), np.round(uv[inside, 0]).astype(int)]
    assert inside.sum() > 1000
    assert np.median(np.abs(z[inside] / truth - 1.0)) < 0.05


def test_slerp_and_track_interpolate_a_turn_and_count_why_frames_are_dropped():
    a, b = Pose.from_euler(0.0, 0.0, 0.2, (0.0, 0.0, 10.0)), Pose.from_euler(0.0, 0.0, 1.0, (4.0, 0.0, 10.0))
    assert Pose(np.zeros(3), slerp(a.orientation, b.orientation, 0.25)).yaw == pytest.approx(0.4)
    assert np.allclose(slerp(a.orientation, -b.orientation, 0.5), slerp(a.orientation, b.orientation, 0.5))
    track = PoseTrack(CameraSettings(max_gap=1.0, gimbal=False, pitch_deg=90.0))
    for t, p in ((2.0, b), (1.0, a), (5.0, b)):  # a late pose is put in order
        track.add(t, p)
    cam = track.camera_at(1.5)
    assert cam.position == pytest.approx([2.0, 0.0, 10.0])
    assert cam.rotation[:, 2] == pytest.approx([0.0, 0.0, -1.0])  # nadir
    assert track.camera_at(0.5) is None and track.camera_at(3.0) is None and track.camera_at(6.0) is None
    assert dict(track.dropped) == {"before the first pose": 1, "telemetry gap": 1, "after the newest pose": 1}
    clock = ClockOffset()
    for stamp, received in ((100.0, 5.3), (100.1, 5.35), (100.2, 5.6)):  # the fastest says offset 94.75
        clock.heard(stamp, received)
    assert clock(6.0) == pytest.approx(100.75)
    with pytest.raises(ConfigError, match="camera.offset"):
        CameraSettings(offset=[0.0, float("nan"), 0.0])
    with pytest.raises(ConfigError, match="camera.max_gap"):
        CameraSettings(max_gap=0.0)


class _MjpegStream:
    """An HTTP MJPEG stream (what many IP cameras serve): 10 frames at 20 Hz per connection, then it drops."""

    def __init__(self) -> None:
        from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

        jpegs = [cv2.imencode(".jpg", np.full((120, 160, 3), 20 * i, np.uint8))[1].tobytes() for i in range(10)]

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                self.send_response(200)
                self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
                self.end_headers()
                for jpeg in jpegs:
                    try:
                        self.wfile.write(b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n"
                                         % len(jpeg) + jpeg + b"\r\n")
                        self.wfile.flush()
                    except (BrokenPipeError, ConnectionResetError):  # the node stopped reading
                        return
                    time.sleep(0.05)

            def log_message(self, *args) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/live.mjpg"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def live_body(t: float) -> Pose:
    return Pose.from_euler(0.0, 0.0, 0.2 * (t - 500.0), (t - 500.0, 2.0 * (t - 500.0), 30.0))


def test_a_live_stream_is_stamped_on_the_autopilots_clock_and_reopened_when_it_drops(flight, caplog):
    _, calibration, _ = flight
    stream = _MjpegStream()
    ep = free_endpoint()
    node_session, test_session = open_session(BusConfig(endpoint=ep)), open_session(BusConfig(endpoint=ep))
    k = keys.Keys("uav1")
    got = []  # (frame, mission time it arrived here)
    t0 = time.monotonic()
    autopilot = lambda: 500.0 + time.monotonic() - t0  # noqa: E731 - the autopilot's clock: another origin
    sub = test_session.declare_subscriber(k.camera, lambda s: got.append(
        (decode_frame(s.payload.to_bytes()).frame, autopilot())))
    node = CameraNode(node_session, "uav1", settings(stream.url, calibration, latency=0.1, reconnect_max=0.5))
    stop, poses_done = threading.Event(), threading.Event()
    publisher = test_session.declare_publisher(k.pose)

    def link() -> None:  # the link node: poses at 20 Hz on the autopilot's clock
        while not poses_done.wait(0.05):
            t = autopilot()
            publisher.put(encode_state(State(t, "uav1", live_body(t))))

    pose_thread = threading.Thread(target=link)
    try:
        node.start()
        wait_for(lambda: publisher.matching_status.matching, "a subscriber of the pose key")
        pose_thread.start()
        wait_for(lambda: len(node.track) >= 3, "the first poses")
        with caplog.at_level(logging.INFO, "layerpilot.camera"):
            runner = threading.Thread(target=node.run, args=(stop,))
            runner.start()
            wait_for(lambda: node.published >= 14 and node.reconnects >= 1, "frames from a second connection")
            stop.set()
            runner.join()
        wait_for_frames(got, node)
    finally:
        poses_done.set()
        if pose_thread.is_alive():
            pose_thread.join()
        sub.undeclare()
        node.stop()
        publisher.undeclare()
        node_session.close()
        test_session.close()
        stream.close()

    messages = [r.getMessage() for r in caplog.records]
    assert sum("no frame (unplugged, busy or the stream dropped)" in m for m in messages) >= 1
    assert any(m.endswith(": frames again") for m in messages)
    assert node.track.dropped == {} and node.published // 2 <= len(got) <= node.published
    for frame, arrived in got:
        # on the autopilot's clock (500 s ahead of this one), exposure = arrival less the 0.1 s latency;
        # the upper bound only leaves room for a loaded machine's transport delay
        assert 0.1 - 1e-9 <= arrived - frame.stamp < 5.0, (arrived, frame.stamp)
        truth = live_body(frame.stamp) @ CameraSettings(pitch_deg=CAMERA.pitch_deg, offset=OFFSET).mount
        assert np.abs(frame.pose.position - truth.position).max() < 1e-6
        assert np.abs(frame.pose.rotation - truth.rotation).max() < 1e-6
        assert frame.intrinsics == CAMERA.intrinsics.scaled(0.5)  # the 320x240 calibration at 160x120


def test_a_refused_stream_is_reopened_with_growing_waits_and_a_bad_file_is_named(flight, tmp_path, caplog):
    video, calibration, _ = flight
    ep = free_endpoint()
    session = open_session(BusConfig(endpoint=ep))
    node = CameraNode(session, "uav1", settings(f"http://127.0.0.1:{_closed_port()}/video.mjpg", calibration,
                                                reconnect_max=0.5))
    stop = threading.Event()
    try:
        with caplog.at_level(logging.WARNING, "layerpilot.camera"):
            runner = threading.Thread(target=node.run, args=(stop,))
            runner.start()
            wait_for(lambda: node.reconnects >= 3, "three reopening attempts")
            stop.set()
            runner.join()
    finally:
        node.stop()
        session.close()
    assert node.kind == "stream" and node.read == 0 and node.supervisor.failure == ""
    assert sum("no frame (unplugged, busy or the stream dropped)" in r.message for r in caplog.records) == 1
    bad = tmp_path / "broken.avi"
    bad.write_bytes(b"not a video")
    with pytest.raises(ValueError, match="cannot read video file .*broken.avi"):
        CameraNode(None, "uav1", settings(bad, calibration))
    with pytest.raises(ValueError, match="camera.calibration"):
        CameraNode(None, "uav1", CameraSettings(source=str(video)))


def _closed_port() -> int:
    from conftest import free_tcp_port

    return free_tcp_port()


def test_layerpilot_camera_runs_a_video_file_to_its_end_against_the_pose_stream(flight, tmp_path):
    video, calibration, _ = flight
    mission = tmp_path / "camera.toml"
    mission.write_text(f"[camera]\npitch_deg = {CAMERA.pitch_deg}\noffset = {OFFSET}\nmax_gap = 0.5\n")
    ep = free_endpoint()
    session = open_session(BusConfig(endpoint=ep))
    k = keys.Keys("uav1")
    got = []
    sub = session.declare_subscriber(k.camera, lambda s: got.append(s.payload.to_bytes()))  # decoded after
    try:
        with cli_process("camera", "--config", str(mission), "--endpoint", ep, "--source", str(video),
                         "--calibration", str(calibration), "--file-start", str(FILE_START),
                         "--status-every", "30") as proc:
            ready = json.loads(proc.stdout.readline())
            assert (ready["node"], ready["status"], ready["kind"]) == ("camera", "ready", "file"), ready
            send_poses(session, k.pose)  # the file's first frame waits for the first pose
            last = json.loads(proc.stdout.readline())
            assert proc.wait(timeout=30) == 0, proc.stderr.read()
        wait_for_frames(got, SimpleNamespace(published=last["published"]))
    finally:
        sub.undeclare()
        session.close()
    # the node's own counts are exact; the frames topic is lossy (a loaded subscriber may miss some)
    assert last["status"] == "stopped" and last["read"] == FRAMES and last["published"] == FRAMES - 8
    assert last["dropped"] == {"before the first pose": 1, "telemetry gap": 5, "after the newest pose": 2}
    stamps = [decode_frame(b).frame.stamp for b in got]
    assert last["errors"] == 0 and len(got) >= (FRAMES - 8) // 2 and len(got) <= FRAMES - 8, len(got)
    assert stamps == sorted(set(stamps))  # in order, none twice


def test_a_mission_with_a_real_camera_runs_the_camera_node_in_the_sim_nodes_place(tmp_path):
    import argparse

    from layerpilot.bus.security import grants, node_user
    from layerpilot.cli.link import link_settings
    from layerpilot.missionfile import load_mission
    from layerpilot.nodes.up import node_commands

    path = tmp_path / "real.toml"
    path.write_text('[camera]\nsource = "rtsp://192.168.1.20/live"\ncalibration = "cam.yaml"\n'
                    '[link.link]\nurl = "udpin:0.0.0.0:14550"\n')
    mission = load_mission(path)
    names = [n.name for n in node_commands(path, mission.vehicles, None, frames="camera")]
    assert names == ["map-server", "camera/uav1", "link/uav1", "depth/uav1", "decide/uav1"]
    assert link_settings(argparse.Namespace(mavlink=None), mission, "uav1").link.url == "udpin:0.0.0.0:14550"
    k, grant = keys.Keys("uav1"), grants(["uav1"])[node_user("camera", "uav1")]
    assert grant.publish == (k.camera, k.health("camera")) and grant.subscribe == (k.pose,)
