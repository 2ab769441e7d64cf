"""`layerpilot sim preview` and `layerpilot bench sim` through the real command."""

from __future__ import annotations

import json

import numpy as np
import pytest

from layerpilot.cli import main


def test_sim_preview_writes_png(tmp_path, capsys):
    cfg = tmp_path / "sim.toml"
    cfg.write_text("[world]\nsize = 150.0\ntrees_per_hectare = 150.0\n[camera]\nwidth = 320\nheight = 240\n")
    out = tmp_path / "preview.png"
    assert main(["sim", "preview", "--config", str(cfg), "--seed", "5", "--agl", "25", "--out", str(out)]) == 0
    import matplotlib.image

    img = matplotlib.image.imread(out)
    assert img.shape[0] > 300 and img.shape[1] > 900  # three panels side by side
    assert np.std(img[..., :3]) > 0.05
    text = capsys.readouterr().out
    assert text.startswith("wrote ")


def test_sim_config_errors_name_the_key(tmp_path, capsys):
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[camera]\nhfov = 90\n")
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


@pytest.mark.parametrize("argv", [["sim", "--rate", "0"]])
def test_sim_run_rejects_bad_rate(argv, capsys):
    assert main(argv + ["--url", "tcp:127.0.0.1:0", "--duration", "0.1"]) == 2
    assert "frame_rate_hz" in capsys.readouterr().err


def test_sim_run_serves_mavlink_and_renders_for_the_given_mission_time(tmp_path, capsys):
    cfg = tmp_path / "sim.toml"
    cfg.write_text("frame_rate_hz = 4.0\n[world]\nsize = 100.0\n[camera]\nwidth = 160\nheight = 120\n")
    assert main(["sim", "--config", str(cfg), "--url", "tcp:127.0.0.1:0", "--duration", "1.0", "--speed", "4"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("layerpilot sim: world seed 0") and "tcp:127.0.0.1:0 -> 127.0.0.1:" in out[0]
    assert "camera 160x120 at 4 Hz" in out[0]
    assert out[-1] == "layerpilot sim: stopped at t=1.00 s after 5 frames"


def test_sim_run_reports_a_busy_port(capsys):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert main(["sim", "--url", f"tcp:127.0.0.1:{port}", "--duration", "0.1"]) == 2
    assert f"tcp:127.0.0.1:{port}" in capsys.readouterr().err
