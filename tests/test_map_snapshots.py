"""Map files you can trust: damaged files are detected whole, snapshots rotate, damage falls back.

Real maps throughout: the real laser scan from the OctoMap project inserted at 0.2 m (with colors
and a stamp, so every attribute is in the file), and the real map geb079.bt as a stock OctoMap file.
"""

from __future__ import annotations

import bz2
import logging
import re
import subprocess
import sys
import threading
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from layerpilot.map import MapFileError, VoxelMap
from layerpilot.map.files import FOOTER_SIZE, footer
from layerpilot.map.snapshots import SnapshotStore
from map_voxels import assert_same_occupancy

REPO = Path(__file__).resolve().parents[1]
BOX = (np.array([-100.0, -100, -30]), np.array([100.0, 100, 30]))


@pytest.fixture(scope="module")
def scan_map(octomap_data: Path) -> VoxelMap:
    points = np.loadtxt(bz2.open(octomap_data / "scan.dat.bz2", "rt"), dtype=np.float32)
    colors = np.random.default_rng(0).integers(0, 256, (len(points), 3), dtype=np.uint8)
    m = VoxelMap(0.2)
    m.insert(points, np.zeros(3), colors, stamp=12.5, max_range=1000.0)
    return m


@pytest.fixture(scope="module")
def snapshot_bytes(scan_map: VoxelMap, tmp_path_factory: pytest.TempPathFactory) -> bytes:
    path = tmp_path_factory.mktemp("snap") / "map.ot"
    size = SnapshotStore(path).save(scan_map)
    data = path.read_bytes()
    assert size == len(data) > 500_000
    return data


def small_map(n_points: int, seed: int = 0) -> VoxelMap:
    """A small real map from random points; distinct n_points give distinct leaf counts."""
    m = VoxelMap(1.0)
    m.insert(np.random.default_rng(seed).uniform(-20, 20, (n_points, 3)).astype(np.float32), np.zeros(3), stamp=1.0)
    return m


def leaves(m: VoxelMap) -> int:
    return m.stats()["leaves"]


def assert_same_map(a: VoxelMap, b: VoxelMap) -> None:
    va, vb = a.voxels(*BOX, min_occupancy=0.0), b.voxels(*BOX, min_occupancy=0.0)
    assert len(va) > 1000
    for name in ("centers", "occupancy", "color", "last_seen", "min_distance"):
        np.testing.assert_array_equal(getattr(va, name), getattr(vb, name), err_msg=name)


def garbage_in_middle(data: bytes) -> bytes:
    mid = len(data) // 2
    return data[:mid] + np.random.default_rng(4).bytes(4096) + data[mid + 4096:]


def garble_header(data: bytes) -> bytes:
    return np.random.default_rng(5).bytes(24) + data[24:]


DAMAGE: dict[str, Callable[[bytes], bytes]] = {
    "truncated to half": lambda d: d[: len(d) // 2],
    "truncated to 100 bytes": lambda d: d[:100],
    "empty": lambda d: b"",
    "garbled header": garble_header,
    "4 KB garbage in the middle": garbage_in_middle,
    "trailing garbage": lambda d: d + b"\0" * 64,
}
# What the one-line message says: with the integrity footer, and for the bare OctoMap stream.
WITH_FOOTER = {"truncated to half": "truncated: the file ends at byte", "truncated to 100 bytes": "truncated",
               "empty": "empty", "garbled header": "damaged: the map stream's SHA-256",
               "4 KB garbage in the middle": "damaged: the map stream's SHA-256",
               "trailing garbage": "trailing garbage"}
BARE = dict(WITH_FOOTER, **{"garbled header": "garbled header: not an OctoMap file",
                            "4 KB garbage in the middle": "garbled node stream at byte"})


def load_error(path: Path) -> str:
    with pytest.raises(MapFileError) as info:
        VoxelMap.load(path)
    message = str(info.value)
    assert isinstance(info.value, ValueError)
    assert message.startswith(f"{path}: ") and "\n" not in message
    return message


@pytest.mark.parametrize("damage", DAMAGE)
@pytest.mark.parametrize("footer_kept", [True, False], ids=["layerpilot file", "bare OctoMap stream"])
def test_damaged_map_files_fail_whole_with_one_line(snapshot_bytes: bytes, tmp_path: Path, damage: str,
                                                    footer_kept: bool) -> None:
    data = snapshot_bytes if footer_kept else snapshot_bytes[:-FOOTER_SIZE]
    path = tmp_path / "map.ot"
    path.write_bytes(DAMAGE[damage](data))
    assert (WITH_FOOTER if footer_kept else BARE)[damage] in load_error(path)


def test_intact_files_load_with_and_without_footer(scan_map: VoxelMap, snapshot_bytes: bytes, tmp_path: Path) -> None:
    (tmp_path / "sealed.ot").write_bytes(snapshot_bytes)
    (tmp_path / "bare.ot").write_bytes(snapshot_bytes[:-FOOTER_SIZE])
    assert_same_map(scan_map, VoxelMap.load(tmp_path / "sealed.ot"))
    assert_same_map(scan_map, VoxelMap.load(tmp_path / "bare.ot"))


def test_truncation_message_names_where_the_stream_ends(snapshot_bytes: bytes, tmp_path: Path) -> None:
    bare = snapshot_bytes[:-FOOTER_SIZE]
    (tmp_path / "map.ot").write_bytes(bare[:5000])
    assert re.search(rf"truncated: the file ends at byte 5000 of {len(bare)} inside the node stream "
                     r"\(\d+ of \d+ nodes read\)$", load_error(tmp_path / "map.ot"))


def octomap_tool(*cmd: str | Path) -> str:
    done = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout + done.stderr


@pytest.fixture(scope="module")
def stock_files(octomap_data: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """geb079.bt as it is, and as the stock OcTree .ot that Debian's convert_octree makes of it."""
    work = tmp_path_factory.mktemp("stock")
    octomap_tool("convert_octree", octomap_data / "geb079.bt", work / "geb079.ot")
    return {".bt": (octomap_data / "geb079.bt").read_bytes(), ".ot": (work / "geb079.ot").read_bytes()}


@pytest.mark.parametrize("suffix", [".bt", ".ot"])
@pytest.mark.parametrize("cut", [0.5, 0.9, -1, 200])
def test_stock_octomap_files_truncated_are_detected(stock_files: dict[str, bytes], tmp_path: Path, suffix: str,
                                                    cut: float) -> None:
    data = stock_files[suffix]
    end = int(len(data) * cut) if isinstance(cut, float) else cut % len(data)
    path = tmp_path / f"geb079{suffix}"
    path.write_bytes(data[:end])
    assert "truncated" in load_error(path)


@pytest.mark.parametrize("suffix", [".bt", ".ot"])
def test_stock_octomap_files_with_garbage_are_detected(stock_files: dict[str, bytes], tmp_path: Path,
                                                       suffix: str) -> None:
    path = tmp_path / f"geb079{suffix}"
    path.write_bytes(garbage_in_middle(stock_files[suffix]))
    assert "garbled" in load_error(path)
    path.write_bytes(stock_files[suffix] + b"x")
    assert "trailing garbage: 1 byte after the node stream ends" in load_error(path)


def test_footer_is_invisible_to_octomap_tools(stock_files: dict[str, bytes], tmp_path: Path) -> None:
    """A stock .ot with layerpilot's footer: convert_octree and compare_octrees read it as before."""
    plain, sealed = tmp_path / "plain.ot", tmp_path / "sealed.ot"
    plain.write_bytes(stock_files[".ot"])
    sealed.write_bytes(stock_files[".ot"] + footer(stock_files[".ot"]))
    assert re.search(r"^KLD: 0$", octomap_tool("compare_octrees", plain, sealed), re.M)
    octomap_tool("convert_octree", sealed, tmp_path / "back.bt")
    assert (tmp_path / "back.bt").read_bytes() == stock_files[".bt"]
    ours = VoxelMap.load(sealed)
    assert assert_same_occupancy(ours, VoxelMap.load(tmp_path / "back.bt")) > 10000
    ours.export_bt(tmp_path / "ours.bt")  # layerpilot's .bt ends in a footer too
    octomap_tool("convert_octree", tmp_path / "ours.bt", tmp_path / "ours.ot")
    assert re.search(r"^KLD: 0$", octomap_tool("compare_octrees", plain, tmp_path / "ours.ot"), re.M)


def test_store_round_trip_keeps_every_attribute(scan_map: VoxelMap, tmp_path: Path) -> None:
    store = SnapshotStore(tmp_path / "runs" / "map.ot")
    assert store.save(scan_map) == (tmp_path / "runs" / "map.ot").stat().st_size
    loaded, events = store.load_newest_good(0.2)
    assert loaded is not None and events == [f"map snapshot {store.path} loaded ({store.path.stat().st_size} bytes)"]
    assert_same_map(scan_map, loaded)


def test_concurrent_saves_all_succeed(scan_map: VoxelMap, tmp_path: Path) -> None:
    path = tmp_path / "map.ot"
    start = threading.Barrier(12)
    sizes: list[int] = []
    errors: list[BaseException] = []

    def save() -> None:
        start.wait()
        try:
            sizes.append(SnapshotStore(path, keep=3).save(scan_map))  # a store per save, as the map service does
        except BaseException as exc:  # noqa: BLE001 - the test reports every failure
            errors.append(exc)

    threads = [threading.Thread(target=save) for _ in range(12)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == [] and len(sizes) == 12 and len(set(sizes)) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.1.ot", "map.2.ot", "map.ot"]  # no temporary left
    for p in tmp_path.iterdir():
        assert_same_map(scan_map, VoxelMap.load(p))


def test_concurrent_plain_saves_to_one_path_all_succeed(tmp_path: Path) -> None:
    maps = [small_map(200 + 50 * i, seed=i) for i in range(12)]
    start = threading.Barrier(12)
    errors: list[BaseException] = []

    def save(m: VoxelMap) -> None:
        start.wait()
        try:
            m.save(tmp_path / "map.ot")
        except BaseException as exc:  # noqa: BLE001
            errors.append(exc)

    threads = [threading.Thread(target=save, args=(m,)) for m in maps]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == [] and [p.name for p in tmp_path.iterdir()] == ["map.ot"]
    assert leaves(VoxelMap.load(tmp_path / "map.ot")) in {leaves(m) for m in maps}


def test_rotation_keeps_the_last_n(tmp_path: Path) -> None:
    store = SnapshotStore(tmp_path / "map.ot", keep=3)
    maps = [small_map(100 * (i + 1)) for i in range(5)]
    for m in maps:
        store.save(m)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.1.ot", "map.2.ot", "map.ot"]
    assert [leaves(VoxelMap.load(p)) for p in store.paths()] == [leaves(m) for m in maps[:1:-1]]


@pytest.fixture
def three_snapshots(tmp_path: Path) -> tuple[SnapshotStore, list[VoxelMap]]:
    store = SnapshotStore(tmp_path / "map.ot", keep=3)
    maps = [small_map(100 * (i + 1)) for i in range(3)]
    for m in maps:
        store.save(m)
    return store, maps[::-1]  # newest first, as store.paths()


def error_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "layerpilot.map" and r.levelno == logging.ERROR]


def test_damaged_newest_falls_back_and_is_moved_aside(three_snapshots, caplog: pytest.LogCaptureFixture) -> None:
    store, maps = three_snapshots
    data = store.path.read_bytes()
    store.path.write_bytes(data[: len(data) // 2])
    with caplog.at_level(logging.ERROR, logger="layerpilot.map"):
        loaded, events = store.load_newest_good(1.0)
    assert loaded is not None and leaves(loaded) == leaves(maps[1])
    assert len(events) == 2 and events[0].startswith(f"damaged map snapshot {store.path}: truncated")
    assert events[1].startswith(f"map snapshot {store.paths()[1]} loaded")
    aside = list(store.path.parent.glob("map.ot.damaged-*"))
    assert len(aside) == 1 and aside[0].read_bytes() == data[: len(data) // 2] and not store.path.exists()
    assert error_lines(caplog) == [events[0]] and f"moved aside to {aside[0].name}" in events[0]
    store.save(maps[0])  # fills the gap: the good ones keep their names, none is dropped
    assert [leaves(VoxelMap.load(p)) for p in store.paths()] == [leaves(maps[0]), leaves(maps[1]), leaves(maps[2])]


def test_all_damaged_gives_none_with_errors(three_snapshots, caplog: pytest.LogCaptureFixture) -> None:
    store, _ = three_snapshots
    for path, damage in zip(store.paths(), ("empty", "garbled header", "4 KB garbage in the middle")):
        path.write_bytes(DAMAGE[damage](path.read_bytes()))
    with caplog.at_level(logging.ERROR, logger="layerpilot.map"):
        loaded, events = store.load_newest_good(1.0)
    assert loaded is None and len(events) == 3
    assert error_lines(caplog) == events
    assert all(e.startswith("damaged map snapshot") and "moved aside to" in e for e in events)
    assert not any(p.exists() for p in store.paths())
    assert len(list(store.path.parent.glob("*.damaged-*"))) == 3


def test_resolution_mismatch_is_an_error_naming_both(three_snapshots, caplog: pytest.LogCaptureFixture) -> None:
    store, _ = three_snapshots
    with caplog.at_level(logging.ERROR, logger="layerpilot.map"):
        loaded, events = store.load_newest_good(0.5)
    assert loaded is None and len(events) == 3 and error_lines(caplog) == events
    assert "has resolution 1 m, the map needs 0.5 m: not loaded" in events[0]
    assert all(p.exists() for p in store.paths())  # not damaged: left in place


def test_no_snapshot_yet_is_no_error(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.ERROR, logger="layerpilot.map"):
        assert SnapshotStore(tmp_path / "map.ot").load_newest_good(1.0) == (None, [])
    assert error_lines(caplog) == []


def test_map_info_on_a_truncated_file_is_one_line_and_no_traceback(snapshot_bytes: bytes, tmp_path: Path) -> None:
    path = tmp_path / "map.ot"
    path.write_bytes(snapshot_bytes[: len(snapshot_bytes) // 2])
    done = subprocess.run([sys.executable, "-m", "layerpilot.cli", "map", "info", str(path)],
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    assert done.returncode != 0 and done.stdout == ""
    assert "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"layerpilot: error: {path}: truncated: the file ends at byte")
