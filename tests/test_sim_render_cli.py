"""`layerpilot sim preview` and `layerpilot bench sim` through the real command."""

from __future__ import annotations

import json

import numpy as np

from layerpilot.cli import main


def test_sim_preview_writes_png(tmp_path, capsys):
    cfg = tmp_path / "sim.toml"
    cfg.write_text("[sim.world]\nsize = 150.0\ntrees_per_hectare = 150.0\n[sim.camera]\nwidth = 320\nheight = 240\n")
    out = tmp_path / "preview.png"
    assert main(["sim", "--seed", "5", "preview", "--config", str(cfg), "--agl", "25", "--out", str(out)]) == 0
    import matplotlib.image

    img = matplotlib.image.imread(out)
    assert img.shape[0] > 300 and img.shape[1] > 900  # three panels side by side
    assert np.std(img[..., :3]) > 0.05
    text = capsys.readouterr().out
    assert text.startswith("wrote ")


def test_sim_config_errors_name_the_key(tmp_path, capsys):
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[sim.camera]\nhfov = 90\n")
    assert main(["sim", "preview", "--config", str(cfg), "--out", str(tmp_path / "x.png")]) == 2
    assert "sim.camera.hfov" in capsys.readouterr().err


def test_bench_sim_prints_fps_and_json_last(capsys):
    assert main(["bench", "sim", "--frames", "2"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert any(line.startswith("640x480:") for line in lines)
    assert any(line.startswith("320x240:") for line in lines)
    result = json.loads(lines[-1])
    assert result["frames"] == 2
    assert result["fps_640x480"] > 0 and result["fps_320x240"] > 0 and result["fps_640x480_no_culling"] > 0
    assert result["triangles"] > 200_000


def test_bench_sim_rejects_zero_frames(capsys):
    assert main(["bench", "sim", "--frames", "0"]) == 2
    assert "frames" in capsys.readouterr().err
