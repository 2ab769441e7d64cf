"""`layerpilot depth preview` and `layerpilot bench depth` end to end (small sizes)."""

from __future__ import annotations

import json

import cv2
import pytest

from layerpilot.cli import main


def test_preview_writes_a_panel(tmp_path, capsys):
    out = tmp_path / "panel.png"
    assert main(["depth", "preview", "--out", str(out), "--size", "320x240", "--pair", "3"]) == 0
    image = cv2.imread(str(out))
    assert image is not None and image.shape[0] > 400 and image.shape[1] > 800
    assert "precision" in capsys.readouterr().out


def test_preview_rejects_a_missing_pair(tmp_path, capsys):
    assert main(["depth", "preview", "--out", str(tmp_path / "x.png"), "--pair", "99"]) == 2
    assert "index" in capsys.readouterr().err


def test_bench_prints_json_last(capsys):
    assert main(["bench", "depth", "--sizes", "320x240", "--repeats", "1"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    result = json.loads(lines[-1])
    (size,) = result["sizes"]
    assert size["size"] == "320x240" and size["pairs"] == 9 and size["picker_accepted"] == 9
    assert size["precision"] >= 0.95 and size["coverage"] >= 0.6 and size["median_abs_rel_error"] < 0.02
    assert size["pairs_per_s"] > 0 and size["opencv_sgbm_only_pairs_per_s"] > 0


def test_bad_size_is_an_error(capsys):
    with pytest.raises(SystemExit):
        main(["bench", "depth", "--sizes", "320by240"])
    assert "WIDTHxHEIGHT" in capsys.readouterr().err
