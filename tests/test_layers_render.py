"""Pictures: every layer and A0..A3 with the waypoint, from the Python function and the command."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from layerpilot.bench.decide import print_decide_bench, run_decide_bench, synthetic_columns
from layerpilot.cli import main
from layerpilot.decide import DecisionMaker, load_behavior
from layerpilot.eval.pictures.layers import render
from layerpilot.layers import LayerContext, compute_layers
from layerpilot.map import VoxelMap


def test_render_writes_every_layer_and_the_decision(tmp_path: Path) -> None:
    columns = synthetic_columns(128)
    layers = compute_layers(columns, LayerContext(now=600.0))
    decision = DecisionMaker(load_behavior("balanced")).decide(layers, (0.0, 0.0, 50.0), 600.0, intermediates=True)
    paths = render(layers, tmp_path, decision, (0.0, 0.0, 50.0), title="test", dpi=60)
    names = {p.stem for p in paths}
    assert names >= {"color", "elevation_m", "fringe", "time", "distance", "elevation",
                     "A0", "A1", "A2", "A3", "Z", "P", "H", "overview"}
    a3 = cv2.imread(str(tmp_path / "A3.png"))
    assert a3 is not None and a3.shape[0] > 250 and a3.shape[1] > 250
    # the waypoint is drawn as a pure red star: such pixels exist on A3 but not on a plain render
    red = lambda img: np.count_nonzero((img[..., 2] > 200) & (img[..., 1] < 40) & (img[..., 0] < 40))  # noqa: E731
    plain = render(layers, tmp_path / "plain", dpi=60)
    assert red(a3) > 20 and red(cv2.imread(str(tmp_path / "plain" / "fringe.png"))) == 0
    assert len(plain) == 1 + 2 + len(layers.names)  # no decision: no A images


def test_layers_render_command_on_a_saved_map(tmp_path: Path, capsys) -> None:
    m = VoxelMap(1.0)
    xs, ys = np.meshgrid(np.arange(-30, 30, 0.5), np.arange(-20, 20, 0.5))
    ground = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)]).astype(np.float32)
    m.insert(ground, np.array([0.0, 0.0, 40.0]), stamp=5.0)
    m.save(tmp_path / "map.ot")
    out = tmp_path / "pics"
    assert main(["layers", "render", "--map", str(tmp_path / "map.ot"), "--behavior", "exploration",
                 "--position", "0", "0", "40", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    for name in ("fringe", "A3", "overview"):
        assert (out / f"{name}.png").stat().st_size > 5000
        assert f"wrote {out / name}.png" in printed
    assert main(["layers", "render", "--map", str(tmp_path / "nope.ot"), "--out", str(out)]) == 2
    assert "no such map file" in capsys.readouterr().err


def test_layers_list_command(capsys) -> None:
    assert main(["layers", "list"]) == 0
    assert capsys.readouterr().out.split() [:4] == ["fringe", "time", "distance", "elevation"]


def test_bench_decide_prints_a_table_and_json_last(capsys) -> None:
    result = run_decide_bench([64, 96], repeat=2)
    print_decide_bench(result)
    lines = capsys.readouterr().out.strip().splitlines()
    assert json.loads(lines[-1]) == result
    assert "64x64" in lines[2] and "96x96" in lines[3]
    for row in result["sizes"].values():
        assert row["total_ms"] > 0 and row["static_total_ms"] > 0 and row["layer_fringe_ms"] > 0
        assert row["same_decision"] and "target_ms" not in row  # targets are for 512 and 1024 only
    for size, row in result["sizes"].items():  # r_i = 100 m reaches past these small grids: the window is all
        assert row["window_cells"] == [int(size)] * 2
    assert result["all_same_decision"]
