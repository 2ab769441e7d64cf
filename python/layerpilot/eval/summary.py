"""Run and study reports from what a mission leaves behind: series, layers, path, settings.

A run directory holds ``metrics.csv`` (the time series) and ``metrics.json`` (the final
values under ``"final"``, the settings under ``"settings"``, the run's own figures such as
``real_time_factor`` at the top); the study report is built from run directories alone, so a
study can be re-reported without flying again.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from layerpilot.eval.milestones import COVERAGE_MILESTONES, never_or_spread, run_milestones
from layerpilot.eval.pictures.plots import LABELS, plot_flight_path, plot_layer, plot_metric
from layerpilot.eval.report import Report, format_value
from layerpilot.eval.series import MetricSeries
from layerpilot.map.columns import ColumnLayers

# The paper's Table 1 columns.
TABLE1 = ["percent_mapped", "avg_time_since_observed", "avg_min_distance", "paper_recall", "paper_mse"]
TABLE1_HEADERS = ["percent observed (%)", "avg time (s)", "avg distance (m)", "3D recall", "3D MSE (m)"]
STANDARD_3D = ["precision", "recall", "f_score"]
ABSOLUTE = "_absolute"  # the same metric without removing the map's offset (eval/alignment.py)
# Scoring up to the offset: what a run holds of these is tabled (absent keys are left out).
OFFSET_COLUMNS = {"percent_mapped": "area (%)", "percent_mapped_absolute": "area absolute (%)",
                  "f_score": "F-score", "f_score_absolute": "F-score absolute",
                  "precision": "precision", "precision_absolute": "precision absolute",
                  "offset_x": "offset x (m)", "offset_y": "offset y (m)", "offset_z": "offset z (m)"}
POSE_COLUMNS = {f"pose_{p}_{k}": f"{p} {text}" for p in ("raw", "refined") for k, text in
                (("position_median", "position median (m)"), ("position_p90", "position p90 (m)"),
                 ("attitude_median_deg", "attitude median (deg)"), ("attitude_p90_deg", "attitude p90 (deg)"),
                 ("poses", "poses compared"))}
FLEET_COLUMNS = {"fleet_min_separation_m": "closest horizontal approach (m)",
                 "fleet_min_height_gap_near_m": "least height gap while nearer than the separation (m)",
                 "fleet_duplicate_coverage": "area seen by 2+ drones (share of seen)"}
# What a run took, beside what it scored: mission seconds per wall-clock second.
RUN_ROWS = {"mission_s": "mission time simulated (s)", "wall_s": "wall-clock time (s)",
            "real_time_factor": "real-time factor (mission s per wall s)"}


def label(name: str) -> str:
    """A metric's readable name; ``*_absolute`` is its base metric's, marked."""
    if name.endswith(ABSOLUTE):
        base = name[: -len(ABSOLUTE)]
        return f"{LABELS.get(base, base)}, absolute"
    if name.startswith("seen_"):
        return f"area seen by {name[len('seen_'):]} (%)"
    return LABELS.get(name) or POSE_COLUMNS.get(name) or FLEET_COLUMNS.get(name) or OFFSET_COLUMNS.get(name, name)


def metric_plots(names: Sequence[str]) -> list[tuple[str, dict[str, str], str]]:
    """A run's plots of its series: (file stem, {line: column}, caption). A metric and its ``*_absolute``
    twin share a plot, and so do the offset's axes: read side by side, and half the plots to draw."""
    offsets = [n for n in names if n.startswith("offset_")]
    plots = []
    for name in names:
        if name.endswith(ABSOLUTE) and name[: -len(ABSOLUTE)] in names or name in offsets[1:]:
            continue
        if name in offsets:
            plots.append(("offset", {n[len("offset_"):]: n for n in offsets}, "map offset, estimated minus true (m)"))
        elif (twin := name + ABSOLUTE) in names:
            plots.append((name, {"aligned to the truth": name, "absolute": twin}, label(name)))
        else:
            plots.append((name, {"": name}, label(name)))
    return plots


def final_table(final: Mapping[str, float]) -> tuple[list[str], list[list[Any]]]:
    """Headers and rows of a run's final metrics: each metric beside its ``*_absolute`` twin when there is one."""
    names = [k for k in final if k != "t" and not (k.endswith(ABSOLUTE) and k[: -len(ABSOLUTE)] in final)]
    if not any(f"{k}{ABSOLUTE}" in final for k in names):
        return ["metric", "value"], [[label(k), final[k]] for k in names]
    return (["metric", "aligned to the truth", "absolute"],
            [[label(k), final[k], final.get(f"{k}{ABSOLUTE}", "")] for k in names])


def write_run_report(
    run_dir: str | os.PathLike,
    title: str,
    series: MetricSeries,
    layers: ColumnLayers,
    aoi: np.ndarray,
    path_xy: np.ndarray | Mapping[str, np.ndarray],
    layer_images: Mapping[str, np.ndarray],
    settings: Mapping[str, Any],
    final_extra: Mapping[str, float] | None = None,
    run: Mapping[str, float] | None = None,
) -> dict[str, Path]:
    """Write the CSV, plots and report.html/.md/metrics.json of one mission into ``run_dir``.

    ``final_extra``: final values that are no time series (e.g. the pose errors over the mission);
    ``run``: what the run took (the keys of RUN_ROWS), a table of its own and top-level keys of metrics.json.
    """
    out = Path(run_dir)
    plots = out / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    series.to_csv(out / "metrics.csv")
    final = {**series.last(), **(final_extra or {})}
    report = Report(title)
    report.heading("Final metrics")
    report.table(*final_table(final))
    report.text(f"Sampled every 10 simulated seconds; last sample at t = {final['t']:.1f} s.")
    if run:
        report.heading("Run")
        report.table(["quantity", "value"], [[RUN_ROWS[k], v] for k, v in run.items()])
    if "offset_x" in final:
        report.text("Aligned: after removing one translation between the map and the true world (offset x/y/z, "
                    "estimated minus true, whole voxels: in a mission the common offset of the camera poses the "
                    "clouds were placed with, 0 with perfect sensors); absolute: without it. Pose errors: position "
                    "after the same translation, attitude as the rotation angle.")
    report.heading("Settings")
    report.table(["setting", "value"], [[k, v] for k, v in settings.items()])
    report.heading("Metrics over time")
    for name, lines, caption in metric_plots(series.names):
        report.image(plot_metric({title: [series]}, lines, plots / f"metric_{name}.png", caption), caption)
    report.heading("Flight path")
    report.image(
        plot_flight_path(layers, path_xy, aoi, plots / "flight_path.png", title),
        "flight path over the color layer; yellow: area of interest",
    )
    report.heading("Final layers")
    for name, values in layer_images.items():
        report.image(plot_layer(values, layers, plots / f"layer_{name}.png", name), name)
    metrics = {**(run or {}), "final": final, "settings": dict(settings)}
    return report.write(out, metrics)


def mean_spread(values: Sequence[float]) -> str:
    """``mean ± std`` over seeds (NaNs ignored), or the single value."""
    finite = [v for v in values if v is not None and not math.isnan(v)]
    if not finite:
        return format_value(float("nan"))
    if len(finite) == 1:
        return format_value(float(finite[0]))
    return f"{np.mean(finite):.4g} ± {np.std(finite, ddof=1):.2g}"


def study_table(finals: Mapping[str, Sequence[Mapping[str, float]]], keys: Sequence[str]) -> list[list[str]]:
    """One row per behavior: its name, then mean ± spread over seeds of each key (a run without it: NaN)."""
    return [[behavior] + [mean_spread([run.get(k, math.nan) for run in runs]) for k in keys]
            for behavior, runs in finals.items()]


def present(finals: Mapping[str, Sequence[Mapping[str, float]]], columns: Mapping[str, str]) -> dict[str, str]:
    """The columns that at least one run has."""
    return {k: h for k, h in columns.items() if any(k in run for runs in finals.values() for run in runs)}


def milestone_table(milestones: Mapping[str, Sequence[Mapping[str, float]]]) -> list[list[str]]:
    """One row per behavior: time to each coverage milestone, paired-frame ratio, retargets (mean ± std)."""
    rows = []
    for behavior, runs in milestones.items():
        times = [never_or_spread([run[f"time_to_{p:g}"] for run in runs]) for p in COVERAGE_MILESTONES]
        rows.append([behavior, *times, mean_spread([run["paired_ratio"] for run in runs]),
                     mean_spread([run["retargets"] for run in runs])])
    return rows


def _final(run_dir: Path) -> dict[str, float]:
    final = json.loads((run_dir / "metrics.json").read_text())["final"]
    return {k: float("nan") if v is None else float(v) for k, v in final.items()}


def _run_rows(dirs: Mapping[str, Sequence[Path]]) -> list[list[Any]]:
    rows = []
    for ds in dirs.values():
        for d in ds:
            metrics = json.loads((d / "metrics.json").read_text())
            s = metrics["settings"]
            rows.append([d.name] + [s.get(k, "–") for k in ("frames", "clouds", "waypoints")] +
                        [metrics.get("wall_s", "–")])
    return rows


def write_study_report(
    out_dir: str | os.PathLike, runs: Mapping[str, Sequence[str | os.PathLike]], settings: Mapping[str, Any],
    behaviors: Mapping[str, str] | None = None,
) -> dict[str, Path]:
    """Compare behaviors from their run directories (several seeds each): Table 1, plots, paths.

    ``behaviors``: each behavior's settings in one line (``Behavior.summary``), shown as flown.
    """
    if not runs or any(not dirs for dirs in runs.values()):
        raise ValueError("runs: every behavior needs at least one run directory")
    out = Path(out_dir)
    plots = out / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    dirs = {b: [Path(d) for d in ds] for b, ds in runs.items()}
    series = {b: [MetricSeries.read_csv(d / "metrics.csv") for d in ds] for b, ds in dirs.items()}
    finals = {b: [_final(d) for d in ds] for b, ds in dirs.items()}
    milestones = {b: [run_milestones(s, json.loads((d / "metrics.json").read_text())["settings"])
                      for s, d in zip(series[b], ds)] for b, ds in dirs.items()}
    report = Report("Behavior study")
    report.heading("Coverage speed and stereo pairing (mean ± std over worlds and seeds)")
    report.table(["behavior", *[f"time to {p:g} % (s)" for p in COVERAGE_MILESTONES], "paired-frame ratio",
                  "retargets"], milestone_table(milestones))
    report.heading("Table 1: final metrics (mean ± std over worlds and seeds)")
    report.table(["behavior"] + TABLE1_HEADERS, study_table(finals, TABLE1))
    report.heading("Standard 3D metrics at d_v = 4 m")
    report.table(["behavior", "precision", "recall (completeness)", "F-score"], study_table(finals, STANDARD_3D))
    for heading, columns in (("Scoring up to the map's offset (mean ± std)", OFFSET_COLUMNS),
                             ("Pose error over the mission (mean ± std)", POSE_COLUMNS),
                             ("Fleets (mean ± std)", FLEET_COLUMNS)):
        if shown := present(finals, columns):
            report.heading(heading)
            report.table(["behavior", *shown.values()], study_table(finals, list(shown)))
    report.heading("Runs")
    report.text("Stereo clouds: camera frames that found a usable stereo partner and reached the map; "
                "a behavior whose motion the picker rejects (e.g. flying straight along the camera's axis) "
                "maps little whatever its path.")
    report.table(["run", "frames", "stereo clouds", "waypoints", "wall (s)"], _run_rows(dirs))
    if behaviors:
        report.heading("Behaviors as flown")
        report.table(["behavior", "settings"], [[b, text] for b, text in behaviors.items()])
    report.heading("Settings")
    report.table(["setting", "value"], [[k, v] for k, v in settings.items()])
    report.heading("Metrics over time")
    for name in next(iter(series.values()))[0].names:
        report.image(plot_metric(series, name, plots / f"metric_{name}.png"), label(name))
    report.heading("Flight paths and final layers (first seed)")
    for behavior, ds in dirs.items():
        for png in sorted((ds[0] / "plots").glob("flight_path.png")) + sorted((ds[0] / "plots").glob("layer_*.png")):
            report.image(png, f"{behavior}: {png.stem.replace('_', ' ')}")
    metrics = {
        "behaviors": {b: {"runs": [str(d) for d in ds], "final": finals[b], "milestones": milestones[b]}
                      for b, ds in dirs.items()},
        "settings": dict(settings),
        "behaviors_as_flown": dict(behaviors or {}),
    }
    return report.write(out, metrics)
