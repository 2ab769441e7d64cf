"""Real photos in (issue 17): EXIF/XMP, skipped photos, refinement and bundle adjustment against the reference
cloud, `map images`.

Uses the real DJI Phantom 3 photos in ../shared/data/brighton_beach; expected metadata values were
read by hand with exifread and from the XMP packet of DJI_0018.JPG.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from layerpilot.cli import main as cli_main
from layerpilot.eval.surface import read_reference, score_points
from layerpilot.photos import PhotoConfig, PhotoStereo, RefineConfig, read_folder, read_metadata
from layerpilot.photos.config import AdjustConfig

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "brighton_beach"
PAIR = ("DJI_0025.JPG", "DJI_0026.JPG")  # second flight line, over the park the reference covers


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """Two real photos and a copy of one whose EXIF GPS pointer is renamed (a photo without a position)."""
    d = tmp_path_factory.mktemp("photos")
    for name in PAIR:
        shutil.copy(DATA / "images" / name, d / name)
    data = bytearray((DATA / "images" / "DJI_0024.JPG").read_bytes())
    at = data.find(b"\x88\x25", 0, 400)  # the GPSInfo tag of IFD0 (big-endian TIFF)
    assert at > 0
    data[at + 1] = 0x26
    (d / "DJI_NOGPS.JPG").write_bytes(bytes(data))
    return d


def test_exif_and_xmp_fields_read_right():
    m = read_metadata(DATA / "images" / "DJI_0018.JPG")
    assert (m.make, m.model, m.width, m.height) == ("DJI", "FC300S", 4000, 2250)
    # GPSLatitude [46, 50, 66771/2000] N, GPSLongitude [91, 59, 101039/2500] W, GPSAltitude 198309/1000
    assert m.lat == pytest.approx(46 + 50 / 60 + 33.3855 / 3600, abs=1e-9)
    assert m.lon == pytest.approx(-(91 + 59 / 60 + 40.4156 / 3600), abs=1e-9)
    assert m.alt == pytest.approx(198.309)
    assert (m.focal_mm, m.focal_35mm) == (pytest.approx(3.61), 20.0)
    assert m.focal_px() == pytest.approx(20 / 36 * 4000)
    assert (m.gimbal_yaw, m.gimbal_pitch, m.gimbal_roll) == (45.0, -89.9, 0.0)
    assert (m.flight_yaw, m.flight_pitch, m.flight_roll) == (46.0, 1.8, 3.0)
    assert m.relative_altitude == pytest.approx(39.8)


def test_photo_without_gps_is_reported_and_skipped(folder):
    f = read_folder(folder)
    assert [p.path.name for p in f.photos] == list(PAIR)
    assert f.skipped == {"DJI_NOGPS.JPG": "no GPS position in EXIF"}
    # the origin lies below the first photo at its take-off height: the camera is 40 m above it
    assert f.frame(0).pose.position == pytest.approx([0.0, 0.0, 40.0], abs=1e-6)
    assert f.frame(0).optical_axis[2] < -0.99  # nadir


def test_refinement_beats_raw_poses_against_the_reference(folder):
    f = read_folder(folder)
    frames = list(f.frames())
    surface = read_reference(DATA / "model.laz", f.origin)
    scores = {}
    for refine in (True, False):
        (pair,) = PhotoStereo(replace(PhotoConfig(), poses="refined" if refine else "raw")).run(frames)
        scores[refine] = (score_points(surface, pair.cloud.points), pair)
    refined, raw = scores[True][0], scores[False][0]
    r = scores[True][1].refinement
    assert r.reason == "ok_heading_flipped" and r.inliers > 300 and r.rotation_correction_deg < 3
    assert refined.scored > 20000 and refined.within_1m > 0.9
    assert raw.within_1m < 0.2
    assert scores[True][1].coverage > 3 * scores[False][1].coverage


def test_bundle_adjustment_beats_pairwise_refinement_against_the_reference():
    """All 12 photos (640 px, 4000 features): one adjusted block against one GNSS baseline per pair.

    The reference only scores; the pipeline never sees it."""
    f = read_folder(DATA / "images", width=640)
    frames = list(f.frames())
    surface = read_reference(DATA / "model.laz", f.origin)
    config = PhotoConfig(width=640, refinement=RefineConfig(features=4000))
    pooled, results = {}, {}
    for poses in ("adjusted", "refined"):
        stereo = PhotoStereo(replace(config, poses=poses))
        pairs = stereo.run(frames)
        scores = [score_points(surface, p.cloud.points) for p in pairs if p.cloud is not None]
        scored = sum(s.scored for s in scores)
        pooled[poses] = sum(s.within_1m * s.scored for s in scores) / scored
        results[poses] = (pairs, stereo.adjustment)
    pairs, adj = results["adjusted"]
    assert all(p.reason == "adjusted" for p in pairs) and len(pairs) == 10
    assert sum(p.accepted for p in results["refined"][0]) == 5  # the forest line's pairs are rejected
    # the second line's recorded heading is half a turn off: the vote turns exactly its six photos
    assert adj.flipped == [False] * 6 + [True] * 6
    assert adj.tracks > 200 and adj.rms_after_px < 1.0 < adj.rms_before_px
    assert max(adj.position_shift_m) < 2.0  # GNSS stays a prior: no camera wanders off
    assert pooled["adjusted"] > 0.85 and pooled["adjusted"] > 2 * pooled["refined"]


def test_adjust_config_names_a_bad_value():
    with pytest.raises(ValueError, match="gnss_sigma_v"):
        AdjustConfig(gnss_sigma_v=0.0)
    with pytest.raises(ValueError, match="loss"):
        AdjustConfig(loss="square")
    with pytest.raises(ValueError, match="poses"):
        PhotoConfig(poses="gnss")


def test_map_images_writes_the_run_directory(folder, tmp_path, capsys):
    out = tmp_path / "run"
    cli_main(["map", "images", str(folder), "--out", str(out), "--width", "640", "--poses", "refined"])
    printed = capsys.readouterr().out
    assert "skipped DJI_NOGPS.JPG: no GPS position in EXIF" in printed
    for name in ("map.ot", "map.bt", "frame.json", "cameras.csv", "pairs.csv", "report.html", "metrics.json",
                 "plots/cameras.png", "plots/layers/color.png", "plots/layers/elevation_m.png"):
        assert (out / name).stat().st_size > 0, name
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["final"]["accepted"] == 1 and metrics["final"]["observed_columns"] > 1000
    cameras = np.genfromtxt(out / "cameras.csv", delimiter=",", names=True, dtype=None, encoding=None)
    assert len(cameras) == 2 and cameras["lat"][0] == pytest.approx(read_metadata(folder / PAIR[0]).lat, abs=1e-7)


def test_gimbal_angles_give_the_camera_axes_in_enu():
    from layerpilot.photos.attitude import camera_rotation

    nadir_north = camera_rotation(0.0, -90.0, 0.0)  # columns: camera x, y, z in ENU
    assert nadir_north == pytest.approx(np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]]), abs=1e-12)
    east = camera_rotation(90.0, -90.0, 0.0)  # heading east: the image's top (-y) points east
    assert -east[:, 1] == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)
    forward = camera_rotation(0.0, 0.0, 0.0)  # level gimbal looking north
    assert forward[:, 2] == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)


def test_calibration_file_overrides_exif_intrinsics(folder, tmp_path):
    import cv2

    from layerpilot.photos.calibration import read_calibration

    path = tmp_path / "cam.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 4000)
    fs.write("image_height", 2250)
    fs.write("camera_matrix", np.array([[2300.0, 0, 2010.0], [0, 2300.0, 1120.0], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.array([[-0.01, 0.01, 0.0, 0.0, 0.0]]))
    fs.release()
    f = read_folder(folder, calibration=read_calibration(path), width=500)
    k = f.frame(0).intrinsics
    assert (k.width, k.fx, k.cx) == (500, pytest.approx(2300 / 8), pytest.approx((2010 + 0.5) / 8 - 0.5))
    bad = tmp_path / "bad.yaml"
    bad.write_text("%YAML:1.0\n---\nimage_width: 4000\nimage_height: 2250\n")
    with pytest.raises(ValueError, match="camera_matrix missing"):
        read_calibration(bad)
    with pytest.raises(ValueError, match="no .jpg photos"):
        read_folder(tmp_path)


def test_bench_photos_finds_the_shared_photos_from_the_working_directory_or_names_the_flags(tmp_path, monkeypatch):
    from layerpilot.bench import photos as bench

    here = tmp_path / "project"
    (tmp_path / "shared" / "data" / "brighton_beach" / "images").mkdir(parents=True)
    here.mkdir()
    monkeypatch.chdir(here)
    assert bench.shared_photos().resolve() == (tmp_path / "shared" / "data" / "brighton_beach").resolve()
    monkeypatch.chdir(tmp_path)  # no ../shared here, and an installed package has none beside it
    monkeypatch.setattr(bench, "__file__", str(tmp_path / "site" / "layerpilot" / "bench" / "photos.py"))
    with pytest.raises(ValueError, match=r"^no default photo folder: pass --folder DIR and --reference FILE"):
        bench.shared_photos()
