"""Map files: .ot round trip with every attribute, .bt for stock OctoMap, and real OctoMap data.

Debian's octomap-tools run OctoMap itself: graph2tree builds the reference map from the real
scan, convert_octree and compare_octrees read what layerpilot writes.
"""

from __future__ import annotations

import bz2
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from layerpilot.bench._octomap import OcTree
from layerpilot.eval.fixtures import survey_clouds
from layerpilot.map import VoxelMap
from map_voxels import assert_same_occupancy


def run(*cmd: str | Path, cwd: Path | None = None) -> str:
    done = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, cwd=cwd, timeout=600)
    assert done.returncode == 0, f"{cmd[0]} failed: {done.stdout}\n{done.stderr}"
    return done.stdout + done.stderr


@pytest.fixture(scope="module")
def small_map() -> VoxelMap:
    m = VoxelMap(1.0)
    for f in survey_clouds(2, seed=9, width=120, height=90):
        m.insert(f.points, f.origin, f.colors, f.stamp)
    return m


def test_ot_round_trip_keeps_every_attribute(small_map: VoxelMap, tmp_path: Path) -> None:
    small_map.save(tmp_path / "map.ot")
    loaded = VoxelMap.load(tmp_path / "map.ot")
    box = (np.array([-300.0, -300, -100]), np.array([300.0, 300, 200]))
    a, b = small_map.voxels(*box, min_occupancy=0.0), loaded.voxels(*box, min_occupancy=0.0)
    assert len(a) > 5000
    for name in ("centers", "occupancy", "color", "last_seen", "min_distance"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    for key in ("leaves", "nodes", "attribute_records"):
        assert loaded.stats()[key] == small_map.stats()[key] > 0, key


def test_bt_export_is_read_by_octomap_tools(small_map: VoxelMap, tmp_path: Path) -> None:
    small_map.export_bt(tmp_path / "map.bt")
    out = run("convert_octree", tmp_path / "map.bt", tmp_path / "stock.ot")
    assert "Reading binary octree type OcTree" in out
    stock = VoxelMap.load(tmp_path / "stock.ot")  # stock OcTree .ot imported
    assert assert_same_occupancy(small_map, stock) > 5000
    assert assert_same_occupancy(small_map, VoxelMap.load(tmp_path / "map.bt")) > 5000


def test_unknown_files_give_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no such map file"):
        VoxelMap.load(tmp_path / "missing.ot")
    with pytest.raises(ValueError, match="expected a .ot or .bt"):
        VoxelMap.load(tmp_path / "map.pcd")
    (tmp_path / "junk.bt").write_bytes(b"not an octree")
    with pytest.raises(ValueError, match="junk.bt: garbled header: not an OctoMap file"):
        VoxelMap.load(tmp_path / "junk.bt")
    with pytest.raises(ValueError, match="writes .ot"):
        VoxelMap(1.0).save(tmp_path / "x.bt")


@pytest.fixture(scope="module")
def scan(octomap_data: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[np.ndarray, Path]:
    """The real scan as points, and as an OctoMap scan graph made by log2graph."""
    work = tmp_path_factory.mktemp("scan")
    text = bz2.open(octomap_data / "scan.dat.bz2", "rt").read()
    (work / "scan.log").write_text("NODE 0 0 0 0 0 0\n" + text)
    run("log2graph", work / "scan.log", work / "scan.graph")
    points = np.loadtxt(text.splitlines(), dtype=np.float32)
    return points, work


@pytest.mark.parametrize("resolution", [0.2, 1.0])
def test_real_scan_matches_octomap_voxel_by_voxel(scan, resolution: float) -> None:
    points, work = scan
    assert points.shape == (88206, 3)
    ref = work / f"ref_{resolution}.bt"
    run("graph2tree", "-i", work / "scan.graph", "-o", ref, "-res", resolution, "-discretize")
    ours = VoxelMap(resolution)
    r = ours.insert(points, np.zeros(3), max_range=1000.0)
    assert r.points_used == 88206
    assert assert_same_occupancy(ours, VoxelMap.load(ref)) > (100000 if resolution == 0.2 else 1500)


def test_whole_map_takes_less_memory_per_leaf_than_stock_octomap_on_the_real_scan(scan) -> None:
    points, _ = scan
    ours, stock = VoxelMap(0.2), OcTree(0.2)
    ours.insert(points, np.zeros(3), max_range=1000.0)
    stock.insert(points, np.zeros(3), 1000.0, True)
    s = ours.stats()
    assert s["leaves"] == pytest.approx(stock.leaves(), rel=0.005) and s["leaves"] > 40000
    # tree with every attribute + column index, against OctoMap's nodes and child arrays alone
    assert s["bytes_per_leaf"] < 0.8 * stock.memory_usage() / stock.leaves()
    assert s["total_bytes"] < stock.memory_usage()


def test_geb079_loads_gives_column_layers_and_saves_back_identically(octomap_data: Path, tmp_path: Path) -> None:
    m = VoxelMap.load(octomap_data / "geb079.bt")
    assert m.resolution == pytest.approx(0.08)
    s = m.stats()
    lo, hi = np.array(s["bounds_min"]), np.array(s["bounds_max"])
    width, height = (np.ceil((hi[:2] - lo[:2]) / m.resolution)).astype(int)
    cl = m.column_layers(lo[0], lo[1], int(width), int(height))
    assert cl.observed.sum() > 10000
    assert np.nanmax(cl.elevation) <= hi[2] + 1e-3 and np.nanmin(cl.elevation) >= lo[2]
    m.export_bt(tmp_path / "geb079.bt")
    assert assert_same_occupancy(m, VoxelMap.load(tmp_path / "geb079.bt")) > 10000
    run("convert_octree", tmp_path / "geb079.bt", tmp_path / "geb079.ot")
    run("convert_octree", octomap_data / "geb079.bt", tmp_path / "orig.ot")
    report = run("compare_octrees", tmp_path / "orig.ot", tmp_path / "geb079.ot")
    assert re.search(r"^KLD: 0$", report, re.M), report
