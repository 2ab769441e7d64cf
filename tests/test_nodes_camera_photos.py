"""A folder of real geotagged photos played as a live camera: frames on the mission clock from their EXIF
capture times, their EXIF/XMP poses published as the telemetry and placed back on the frames by the
camera node, on real Zenoh (the shared Brighton Beach photos)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from layerpilot.bus import keys
from layerpilot.bus.messages import decode_frame, decode_state
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.mission.camera_track import CameraSettings
from layerpilot.nodes.camera import CameraNode
from layerpilot.photos.player import open_player

from conftest import SHARED, wait_for

BRIGHTON = SHARED / "data" / "brighton_beach"
# DJI_0018..0023 every 7 s, then the second line 9 s later, every 7 s (EXIF DateTimeOriginal)
CAPTURED = [0.0, 7.0, 14.0, 21.0, 28.0, 35.0, 44.0, 51.0, 58.0, 65.0, 72.0, 79.0]


def photo_settings(source: Path, **changes) -> CameraSettings:
    return CameraSettings(source=str(source), pitch_deg=90.0, gimbal=False, file_start=100.0, **changes)


def test_a_project_folder_plays_in_capture_order_and_its_poses_survive_the_mount() -> None:
    settings = photo_settings(BRIGHTON)  # the project folder: its photos are in images/
    player = open_player(BRIGHTON, settings.mount, settings.file_start)
    assert len(player) == 12 and not player.folder.skipped
    assert player.stamps.tolist() == [100.0 + t for t in CAPTURED]
    for i in (0, 11):  # the telemetry pose with the mount put back is the photo's camera
        camera = player.body_pose(i) @ settings.mount
        assert np.abs(camera.matrix - player.camera_pose(i).matrix).max() < 1e-12
    assert player.frame(3).stamp == 121.0 and player.frame(3).image.shape == (562, 1000, 3)


def test_the_camera_node_plays_photos_as_frames_and_telemetry_at_their_pace() -> None:
    settings = photo_settings(BRIGHTON / "images", play_rate=40.0)
    ep = free_endpoint()
    node_session, test_session = open_session(BusConfig(endpoint=ep)), open_session(BusConfig(endpoint=ep))
    k = keys.Keys("uav1")
    frames, poses, arrived = [], [], []
    subs = [test_session.declare_subscriber(k.camera, lambda s: (frames.append(decode_frame(s.payload.to_bytes())),
                                                                 arrived.append(time.monotonic()))),
            test_session.declare_subscriber(k.pose, lambda s: poses.append(decode_state(s.payload.to_bytes())))]
    node = CameraNode(node_session, "uav1", settings)
    stop = threading.Event()
    runner = threading.Thread(target=node.run, args=(stop,))
    try:
        node.start()
        runner.start()
        wait_for(lambda: node.read > len(node.player), "the folder to play", timeout=120.0)
        wait_for(lambda: len(frames) == node.published and len(poses) == 12, "the frames and poses to arrive")
        assert runner.is_alive()  # a played folder leaves the node idle: `up` does not replay it
    finally:
        stop.set()
        runner.join(timeout=10.0)
        for sub in subs:
            sub.undeclare()
        node.stop()
        node_session.close()
        test_session.close()

    player = node.player
    assert node.published == 12 and not node.track.dropped and node.status()["source"] == "photos"
    assert [p.stamp for p in poses] == [100.0 + t for t in CAPTURED]
    assert [m.frame.stamp for m in frames] == [100.0 + t for t in CAPTURED]
    for i, m in enumerate(frames):  # placed from the telemetry, where the photo's metadata says
        assert np.abs(m.frame.pose.matrix - player.camera_pose(i).matrix).max() < 1e-9
        assert m.frame.intrinsics == player.frame(i).intrinsics and m.frame.intrinsics.width == 1000
    # paced by the capture times at 40x: no photo goes out before its capture time / 40 after the first
    # (a load on the machine only delays arrivals, so this bound holds however busy it is)
    assert all(a >= node._played_from + t / 40.0 for a, t in zip(arrived, CAPTURED))
    assert arrived[-1] - node._played_from >= 79.0 / 40.0


def test_a_photo_folder_needs_the_camera_unlevelled() -> None:
    session = open_session(BusConfig(endpoint=free_endpoint()))
    try:
        with pytest.raises(ValueError, match="camera.gimbal"):
            CameraNode(session, "uav1", CameraSettings(source=str(BRIGHTON), gimbal=True))
    finally:
        session.close()


def test_photos_through_up_map_as_accurately_as_map_images(tmp_path) -> None:
    """camera -> depth -> map server under `up`; the map's elevation against the reference surface
    within 0.1 m (median) of what `layerpilot map images` makes of the same photos."""
    import re

    from layerpilot.bus.session import free_endpoint as endpoint
    from layerpilot.eval.photo_run import PhotoMap, build_photo_map, map_columns
    from layerpilot.eval.surface import read_reference, score_elevation
    from layerpilot.map import VoxelMap
    from layerpilot.photos import PhotoConfig, read_folder

    from conftest import start_up, stop_up

    mission = tmp_path / "photos.toml"
    mission.write_text(f'vehicles = ["uav1"]\n[map_server]\nresolution = 0.5\nwindow = [-100.0, -100.0, 400, 400]\n'
                       f'snapshot = "{tmp_path / "map.ot"}"\n[camera]\nsource = "{BRIGHTON}"\npitch_deg = 90.0\n'
                       'gimbal = false\nplay_rate = 3.0\n[depth]\nqueue_size = 12\n')  # the folder fits: none dropped
    up, lines = start_up(mission, endpoint(), tmp_path / "logs")
    try:
        try:
            wait_for(lambda: any(re.search(r"depth/uav1 .* frames=12 ", line) for line in lines),
                     "the depth node to take the 12 photos", timeout=300.0)
        except AssertionError as exc:  # say how far each node got
            last = {line.split()[0]: line for line in lines if line.strip()}
            raise AssertionError(f"{exc}; last lines: {list(last.values())[-6:]}") from None
    finally:
        stop_up(up)
    depth = [line for line in lines if line.startswith("depth/uav1")][-1]
    assert int(re.search(r" clouds=(\d+)", depth).group(1)) > 0 and " dropped=0 " in depth, depth
    folder = read_folder(BRIGHTON)
    surface = read_reference(BRIGHTON / "model.laz", folder.origin)
    live = VoxelMap.load(tmp_path / "map.ot")
    cameras = np.array([folder.position(m) for m in folder.photos])
    live_cols = map_columns(PhotoMap(folder, live, [], cameras))
    live_score = score_elevation(surface, live_cols.elevation, live_cols.geometry)
    offline = build_photo_map(folder, PhotoConfig()).columns
    offline_score = score_elevation(surface, offline.elevation, offline.geometry)
    print(f"elevation error median: live {live_score.median:.3f} m over {live_score.columns} cells, "
          f"map images {offline_score.median:.3f} m over {offline_score.columns}; {depth}")
    assert live_score.columns > 0.8 * offline_score.columns
    assert abs(live_score.median - offline_score.median) <= 0.1


def test_a_photo_mission_runs_camera_and_depth_only_and_only_its_camera_may_publish_poses(tmp_path) -> None:
    from layerpilot.bus.security import grants, node_user
    from layerpilot.config import ConfigError
    from layerpilot.missionfile import load_mission
    from layerpilot.nodes.up import frames_of, node_commands

    path = tmp_path / "photos.toml"
    path.write_text(f'[camera]\nsource = "{BRIGHTON}"\ngimbal = false\n')
    mission = load_mission(path)
    assert frames_of(mission.camera.source) == "photos" and frames_of("flight.avi") == "camera"
    assert mission.core.depth.pairs == "survey" and load_mission("default").core.depth.pairs == "video"
    (tmp_path / "bad.toml").write_text('[depth]\npairs = "photos"\n')
    with pytest.raises(ConfigError, match=r"depth.pairs: expected one of 'auto', 'video', 'survey', got 'photos'"):
        load_mission(tmp_path / "bad.toml")
    names = [n.name for n in node_commands(path, mission.vehicles, None, frames="photos")]
    assert names == ["map-server", "camera/uav1", "depth/uav1"]  # nothing flies: no link, no decide
    k, camera = keys.Keys("uav1"), node_user("camera", "uav1")
    assert k.pose in grants(["uav1"], photos=True)[camera].publish
    assert k.pose not in grants(["uav1"])[camera].publish  # a real camera beside a link may not


def test_photos_without_a_capture_time_or_at_the_same_time_are_skipped_with_the_reason(tmp_path) -> None:
    import shutil

    first, second = BRIGHTON / "images" / "DJI_0018.JPG", BRIGHTON / "images" / "DJI_0019.JPG"
    shutil.copy(first, tmp_path / "a.jpg")
    shutil.copy(first, tmp_path / "b.jpg")  # the same capture time as a.jpg
    data = second.read_bytes()
    assert data.count(b"2016:06:23 16:32:06") >= 1
    (tmp_path / "c.jpg").write_bytes(data.replace(b"2016:06:23 16:32:06", b"0000:00:00 00:00:00"))
    player = open_player(tmp_path, photo_settings(tmp_path).mount)
    assert [m.path.name for m in player.folder.photos] == ["a.jpg"] and player.stamps.tolist() == [0.0]
    assert player.folder.skipped == {"b.jpg": "taken at the same time as a.jpg",
                                     "c.jpg": "no capture time in EXIF (DateTimeOriginal)"}
    (tmp_path / "a.jpg").unlink()
    (tmp_path / "b.jpg").unlink()
    with pytest.raises(ValueError, match="no photo has a capture time"):
        open_player(tmp_path, photo_settings(tmp_path).mount)
