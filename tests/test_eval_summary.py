"""Run and study reports from a real map filled over time and sampled like a mission."""

from __future__ import annotations

import base64
import json
import re

import numpy as np
import pytest

from layerpilot.eval.metrics import area_metrics, disk_mask, map_voxel_metrics
from layerpilot.eval.series import SeriesSampler
from layerpilot.eval.summary import mean_spread, write_run_report, write_study_report
from layerpilot.grid import GridGeometry

NAMES = ["percent_mapped", "avg_time_since_observed", "avg_min_distance", "paper_recall", "paper_mse",
         "precision", "recall", "f_score"]


def _fly(run_dir, speed: float, seed: int):
    """A sensor sweeping east over flat ground at z = 0, seeing a 10 m wide strip below it."""
    from layerpilot.map import VoxelMap

    rng = np.random.default_rng(seed)
    est, gt = VoxelMap(1.0), VoxelMap(1.0)
    g = GridGeometry.centered(0.0, 0.0, 1.0, 60, 60)
    aoi = disk_mask(g, (0.0, 0.0), 25.0)
    sampler = SeriesSampler(NAMES)
    lo, hi = np.array([-30.0, -30, -5]), np.array([30.0, 30, 5])
    path = []
    for step in range(0, 31):
        t = step * 2.0
        x = -28.0 + speed * t
        path.append((x, 0.0))
        gx, gy = np.meshgrid(np.arange(x - 5, x + 5, 0.5), np.arange(-5, 5, 0.5))
        ground = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, 0.2)], 1).astype(np.float32)
        origin = np.array([x, 0.0, 10.0])
        colors = np.tile(np.array([[30, 160, 40]], np.uint8), (len(ground), 1))
        gt.insert(ground, origin, colors, stamp=t)
        noisy = ground + rng.normal(0, 0.4, ground.shape).astype(np.float32)
        est.insert(noisy, origin, colors, stamp=t)

        def compute() -> dict[str, float]:
            layers = est.column_layers_for(g)
            return {**area_metrics(layers, aoi, t).as_dict(), **map_voxel_metrics(est, gt, lo, hi).as_dict()}

        sampler.maybe_sample(t, compute)
    layers = est.column_layers_for(g)
    paths = write_run_report(
        run_dir, f"sweep {speed}", sampler.series, layers, aoi, np.array(path),
        {"elevation": layers.elevation}, {"speed_m_s": speed, "seed": seed},
    )
    return sampler.series, paths


def test_run_report_has_every_section_and_sensible_values(tmp_path) -> None:
    series, paths = _fly(tmp_path / "run", 1.0, 0)
    mapped = series.column("percent_mapped")
    assert len(series) == 7 and series.column("t")[-1] == 60.0
    assert mapped[0] > 0 and np.all(np.diff(mapped) > 0) and mapped[-1] <= 100.0
    assert 0 < series.column("precision")[-1] <= 1 and 0 < series.column("recall")[-1] <= 1
    final = json.loads(paths["json"].read_text())["final"]
    assert final["percent_mapped"] == pytest.approx(mapped[-1])
    assert final["avg_min_distance"] == pytest.approx(10.0, abs=1.5)  # ground ~10 m below the sensor
    page = paths["html"].read_text()
    for section in ["Final metrics", "Settings", "Metrics over time", "Flight path", "Final layers"]:
        assert f"<h2>{section}</h2>" in page
    images = re.findall(r"base64,([A-Za-z0-9+/=]+)", page)
    assert len(images) == len(series.names) + 2
    assert all(base64.b64decode(i)[:8] == b"\x89PNG\r\n\x1a\n" for i in images)
    assert (tmp_path / "run" / "metrics.csv").read_text().startswith("t,percent_mapped,")


def test_study_report_compares_behaviors_over_seeds(tmp_path) -> None:
    runs = {
        "fast": [_fly(tmp_path / f"fast{s}", 1.0, s)[1]["json"].parent for s in (0, 1)],
        "slow": [_fly(tmp_path / "slow0", 0.4, 0)[1]["json"].parent],
    }
    paths = write_study_report(tmp_path / "study", runs, {"seeds": 2})
    md = paths["md"].read_text()
    rows = {line.split(" | ")[0].strip("| "): line for line in md.splitlines() if line.startswith("| fast") or
            line.startswith("| slow")}
    assert "±" in rows["fast"] and "±" not in rows["slow"].split(" | ")[1]
    data = json.loads(paths["json"].read_text())["behaviors"]
    fast = np.mean([r["percent_mapped"] for r in data["fast"]["final"]])
    assert fast > data["slow"]["final"][0]["percent_mapped"]  # flying faster covers more of the disk
    page = paths["html"].read_text()
    assert "Table 1" in page and page.count(">fast: flight path<") == 1
    assert page.count(">slow: layer elevation<") == 1
    with pytest.raises(ValueError, match="runs"):
        write_study_report(tmp_path / "x", {"fast": []}, {})


def test_mean_spread() -> None:
    assert mean_spread([1.0, 3.0]) == "2 ± 1.4"
    assert mean_spread([float("nan"), 2.0]) == "2"
    assert mean_spread([None]) == "–"
