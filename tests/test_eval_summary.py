"""Run and study reports from a real map filled over time and sampled like a mission."""

from __future__ import annotations

import base64
import json
import re

import numpy as np
import pytest

from layerpilot.eval.alignment import MapScorer
from layerpilot.eval.metrics import disk_mask
from layerpilot.eval.pose_errors import pose_errors
from layerpilot.eval.series import SeriesSampler
from layerpilot.eval.summary import mean_spread, metric_plots, write_run_report, write_study_report
from layerpilot.geometry import Pose
from layerpilot.grid import GridGeometry


def _fly(run_dir, speed: float, seed: int, lift: float = 0.0):
    """A sensor sweeping east over flat ground at z = 0, seeing a 10 m wide strip below it.

    The estimated map is ``lift`` metres above the truth (a GNSS height error); the sensor's
    true and estimated positions give the pose errors.
    """
    from layerpilot.map import VoxelMap

    rng = np.random.default_rng(seed)
    est, gt = VoxelMap(1.0), VoxelMap(1.0)
    g = GridGeometry.centered(0.0, 0.0, 1.0, 60, 60)
    aoi = disk_mask(g, (0.0, 0.0), 25.0)
    lo, hi = np.array([-30.0, -30, -5]), np.array([30.0, 30, 5])
    scorer = MapScorer(g, aoi, lo, hi)
    sampler = SeriesSampler(scorer.names)
    path, truth, estimate = [], [], []
    for step in range(0, 31):
        t = step * 2.0
        x = -28.0 + speed * t
        path.append((x, 0.0))
        gx, gy = np.meshgrid(np.arange(x - 5, x + 5, 0.5), np.arange(-5, 5, 0.5))
        ground = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, 0.2)], 1).astype(np.float32)
        origin = np.array([x, 0.0, 10.0])
        colors = np.tile(np.array([[30, 160, 40]], np.uint8), (len(ground), 1))
        gt.insert(ground, origin, colors, stamp=t)
        noisy = ground + rng.normal(0, 0.4, ground.shape).astype(np.float32) + np.float32([0, 0, lift])
        est.insert(noisy, origin + (0, 0, lift), colors, stamp=t)
        truth.append((t, Pose(origin)))
        estimate.append((t, Pose(origin + (0.0, 0.0, lift + rng.normal(0, 0.3)))))
        sampler.maybe_sample(t, lambda: scorer(est, gt, t))
    layers = est.column_layers_for(g)
    offset = [sampler.series.last()[k] for k in ("offset_x", "offset_y", "offset_z")]
    paths = write_run_report(
        run_dir, f"sweep {speed}", sampler.series, layers, aoi, np.array(path),
        {"elevation": layers.elevation}, {"speed_m_s": speed, "seed": seed},
        final_extra=pose_errors(truth, estimate, offset).as_dict("pose_raw"),
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
    plots = metric_plots(series.names)  # each metric beside its absolute twin, the offset's axes together
    assert sorted(c for _, lines, _ in plots for c in lines.values()) == sorted(series.names)
    assert {"aligned to the truth": "f_score", "absolute": "f_score_absolute"} in [lines for _, lines, _ in plots]
    assert len(images) == len(plots) + 2 and len(plots) < len(series.names)
    assert all(base64.b64decode(i)[:8] == b"\x89PNG\r\n\x1a\n" for i in images)
    assert (tmp_path / "run" / "metrics.csv").read_text().startswith("t,percent_mapped,")
    assert final["offset_z"] == 0.0 and final["f_score"] == final["f_score_absolute"]  # zero-mean noise: no offset
    assert final["pose_raw_position_median"] == pytest.approx(0.3 * 0.674, abs=0.1)  # median |N(0, 0.3)|
    assert "<th>aligned to the truth</th><th>absolute</th>" in page and "<td>raw position p90 (m)</td>" in page


def test_a_lifted_map_is_scored_after_its_offset_and_without_it(tmp_path) -> None:
    series, paths = _fly(tmp_path / "run", 1.0, 0, lift=2.0)
    final = json.loads(paths["json"].read_text())["final"]
    assert (final["offset_x"], final["offset_y"], final["offset_z"]) == (0.0, 0.0, 2.0)
    assert final["paper_mse_absolute"] - final["paper_mse"] > 0.8  # the 2 m lift is not counted
    assert final["pose_raw_position_median"] < 0.5  # the lift is removed from the pose errors too
    md = paths["md"].read_text()
    assert "| 3D MSE (paper, m), absolute |" not in md  # one row per metric, its absolute value beside it
    assert re.search(r"\| 3D MSE \(paper, m\) \| [0-9.]+ \| [0-9.]+ \|", md)


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
    assert "<h2>Scoring up to the map&#x27;s offset (mean ± std)</h2>" in page
    assert "<h2>Pose error over the mission (mean ± std)</h2>" in page and "<th>raw position p90 (m)</th>" in page
    assert "refined position" not in page  # what no run holds is left out
    with pytest.raises(ValueError, match="runs"):
        write_study_report(tmp_path / "x", {"fast": []}, {})


def test_mean_spread() -> None:
    assert mean_spread([1.0, 3.0]) == "2 ± 1.4"
    assert mean_spread([float("nan"), 2.0]) == "2"
    assert mean_spread([None]) == "–"
