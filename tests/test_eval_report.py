"""Reports: HTML with inline images, Markdown with linked images, strict JSON metrics."""

from __future__ import annotations

import base64
import json
import re

import cv2
import numpy as np
import pytest

from layerpilot.eval.report import Report


def test_report_files_written_and_read_back(tmp_path) -> None:
    png = tmp_path / "plots" / "a.png"
    png.parent.mkdir()
    cv2.imwrite(str(png), np.full((8, 12, 3), 200, np.uint8))
    r = Report("Run <demo>")
    r.heading("Metrics")
    r.table(["metric", "value"], [["area mapped (%)", 42.123456], ["3D MSE (m)", float("nan")]])
    r.text("a & b")
    r.image(png, "area over time")
    paths = r.write(tmp_path, {"percent_mapped": 42.123456, "paper_mse": float("nan"), "n": np.int64(3)})

    page = paths["html"].read_text()
    assert "<title>Run &lt;demo&gt;</title>" in page and "a &amp; b" in page
    assert "<td>42.12</td>" in page and "<td>–</td>" in page
    inline = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(inline) == 1 and base64.b64decode(inline[0]) == png.read_bytes()
    assert "src=\"plots" not in page  # self-contained: no file references

    md = paths["md"].read_text()
    assert "| area mapped (%) | 42.12 |" in md and "![area over time](plots/a.png)" in md

    assert json.loads(paths["json"].read_text()) == {"percent_mapped": 42.123456, "paper_mse": None, "n": 3}


def test_report_rejects_bad_input(tmp_path) -> None:
    r = Report("x")
    with pytest.raises(ValueError, match="rows"):
        r.table(["a", "b"], [[1]])
    with pytest.raises(ValueError, match="path"):
        r.image(tmp_path / "missing.png")
