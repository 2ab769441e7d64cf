"""The map's commands: building a map from the real scan, and the side-by-side benchmark."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from layerpilot.bench.map import print_map_bench, run_map_bench, run_memory_bench
from layerpilot.cli import main
from layerpilot.eval.fixtures import survey_clouds
from layerpilot.map import VoxelMap


def test_map_scan_writes_maps_and_pictures(octomap_data: Path, tmp_path: Path, capsys) -> None:
    assert main(["map", "scan", str(octomap_data / "scan.dat.bz2"), "--out", str(tmp_path), "--resolution", "0.5"]) == 0
    out = capsys.readouterr().out
    for name in ("map.ot", "map.bt", "elevation.png", "color.png"):
        assert (tmp_path / name).stat().st_size > 1000, name
        assert f"wrote {tmp_path / name}" in out
    m = VoxelMap.load(tmp_path / "map.ot")
    assert m.resolution == 0.5 and m.stats()["occupied_leaves"] > 1000
    assert main(["map", "info", str(tmp_path / "map.bt")]) == 0
    assert "occupied_leaves" in capsys.readouterr().out


def test_map_scan_rejects_a_file_that_is_not_a_scan(tmp_path: Path, capsys) -> None:
    (tmp_path / "bad.txt").write_text("1 2\n3 4\n")
    assert main(["map", "scan", str(tmp_path / "bad.txt"), "--out", str(tmp_path / "o")]) == 2
    assert "expected 3 columns" in capsys.readouterr().err


def test_bench_map_reports_every_figure(capsys) -> None:
    frames = survey_clouds(2, seed=1, width=96, height=72)
    result = run_map_bench(frames)
    print_map_bench(result)
    last = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert last == result
    assert result["voxels_identical"] == result["voxels_compared"] > 1000
    assert result["points_per_frame"] == int(np.mean([len(f) for f in frames])) > 0.5 * 96 * 72
    for key in ("layerpilot_ms", "octomap_discretized_ms", "octomap_default_ms", "column_layers_512_ms"):
        assert result[key] > 0, key
    assert result["node_bytes"] == 8 and result["leaves"] > 1000
    assert np.isfinite(result["ratio_vs_default"]) and np.isfinite(result["ratio_vs_discretized"])


def test_bench_map_memory_on_a_surveyed_world(capsys) -> None:
    result = {"memory": run_memory_bench(150.0, seed=2)}  # 2 survey lines of 3 frames
    print_map_bench(result | run_map_bench(survey_clouds(1, seed=1, width=64, height=48)))
    out = capsys.readouterr().out
    assert "OctoMap / layerpilot memory" in out
    m = json.loads(out.strip().splitlines()[-1])["memory"]
    assert m == result["memory"]
    assert m["survey_frames"] == 6 and m["leaves"] > 20000
    assert abs(m["leaves"] - m["octomap_leaves"]) <= 0.001 * m["octomap_leaves"]  # the same tree
    assert m["attribute_records"] > 1000
    # the whole map, every attribute, under OctoMap's occupancy-only tree on the same data
    assert m["bytes_per_leaf"] < m["octomap_bytes_per_leaf"] and m["ratio_memory"] > 1
    assert m["bytes_per_leaf"] < m["bytes_per_leaf_with_insert_scratch"]
    assert abs(m["total_mib"] - m["tree_mib"] - m["column_index_mib"]) <= 0.01


def test_map_images_with_one_usable_photo_says_no_pair_could_be_made(tmp_path: Path, capsys) -> None:
    """One real DJI photo: no pair, so no depth and no map: an error, exit 2, nothing written."""
    photos = tmp_path / "photos"
    photos.mkdir()
    images = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "brighton_beach" / "images"
    first = sorted(images.glob("*.JPG"))[0]
    (photos / first.name).write_bytes(first.read_bytes())
    assert main(["map", "images", str(photos), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"layerpilot: error: {photos}: only 1 usable photo ({first.name}): no pair could be made; "
                   "a map needs at least two overlapping photos")
    assert not (tmp_path / "run").exists()
