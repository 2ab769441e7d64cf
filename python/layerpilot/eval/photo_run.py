"""A map from a folder of photos, written as a run directory like a mission's.

photos -> pairs (picked, refined, matched) -> voxel map -> layers. The run directory holds
``map.ot``/``map.bt``, ``frame.json`` (where the map frame lies on the Earth), ``cameras.csv``
(every photo's camera position in the map frame and on the Earth), ``pairs.csv`` (what happened
to every pair), the layer pictures over the color layer and ``report.html``/``.md``/``metrics.json``.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from layerpilot.eval.pictures.layers import render
from layerpilot.eval.pictures.plots import plot_flight_path
from layerpilot.eval.report import Report
from layerpilot.eval.run_frame import write_run_frame
from layerpilot.grid import GridGeometry
from layerpilot.layers import LayerContext, compute_layers
from layerpilot.map import VoxelMap
from layerpilot.map.columns import ColumnLayers
from layerpilot.photos import PairResult, PhotoConfig, PhotoFolder, PhotoStereo
from layerpilot.depth.adjust import Adjustment
from layerpilot.progress import Progress


@dataclass
class PhotoMap:
    folder: PhotoFolder
    map: VoxelMap
    pairs: list[PairResult]
    cameras: np.ndarray  # (N, 3) camera centres in the map frame, photo order (GNSS)
    adjustment: Adjustment | None = None  # with bundle-adjusted poses
    columns: ColumnLayers | None = None
    paths: dict[str, Path] = field(default_factory=dict)


def build_photo_map(folder: PhotoFolder, config: PhotoConfig = PhotoConfig(), stream: TextIO | None = None,
                    label: str = "photos") -> PhotoMap:
    """Every pair's cloud into one voxel map (stamp = the photo's index), with a progress bar."""
    n = len(folder.photos)
    progress = Progress(2 * n, label, " steps", stream)  # load every photo, then refine and match each pair
    frames = []
    for i in range(n):
        frames.append(folder.frame(i))
        progress.update(i + 1, f"loaded {i + 1}/{n} photos")
    stereo = PhotoStereo(config)
    pairs = stereo.run(frames, lambda done, total: progress.update(n + n * done / max(total, 1), f"pairs {done}/{total}"))
    m = VoxelMap(config.resolution)
    for pair in pairs:
        if (c := pair.cloud) is not None:
            m.insert(c.points, c.origin, c.colors, c.stamp, config.match.max_depth)
    progress.close(f"pairs {sum(p.accepted for p in pairs)}/{len(pairs)} accepted")
    result = PhotoMap(folder, m, pairs, np.array([f.pose.position for f in frames]).reshape(-1, 3), stereo.adjustment)
    result.columns = map_columns(result)
    return result


def map_columns(photo_map: PhotoMap, margin: float = 20.0) -> ColumnLayers:
    """Column layers over the cameras plus ``margin`` metres (a photo sees about its height around it)."""
    res = photo_map.map.resolution
    lo = np.floor((photo_map.cameras[:, :2].min(0) - margin) / res) * res
    hi = np.ceil((photo_map.cameras[:, :2].max(0) + margin) / res) * res
    w, h = (np.round((hi - lo) / res)).astype(int)
    return photo_map.map.column_layers_for(GridGeometry(float(lo[0]), float(lo[1]), res, int(w), int(h)))


def pair_rows(pairs: list[PairResult], folder: PhotoFolder) -> list[dict]:
    name = lambda i: folder.photos[i].path.name  # noqa: E731
    rows = []
    for p in pairs:
        r = p.refinement
        rows.append({"ref": name(p.ref), "partner": name(p.partner), "baseline_ratio": round(p.baseline_ratio, 3),
                     "result": p.reason, "matches": r.matches if r else "", "inliers": r.inliers if r else "",
                     "rotation_correction_deg": round(r.rotation_correction_deg, 2) if r else "",
                     "direction_correction_deg": round(r.direction_correction_deg, 2) if r else "",
                     "points": len(p.cloud) if p.cloud is not None else 0,
                     "overlap_coverage": "" if math.isnan(p.coverage) else round(p.coverage, 3)})
    return rows


def adjustment_rows(adj: Adjustment) -> list[list]:
    """What the bundle adjustment did, as (quantity, value) rows."""
    focal, k1, k2 = adj.lens
    return [["photos adjusted", sum(f is not None for f in adj.frames)], ["verified photo pairs", len(adj.links)],
            ["tracks (3+ photos)", adj.tracks], ["observations", adj.observations],
            ["reprojection rms before / after (px)", f"{adj.rms_before_px:.2f} / {adj.rms_after_px:.2f}"],
            ["headings turned half a turn", sum(adj.flipped)],
            ["focal factor, k1, k2", f"{focal:.4f}, {k1:.4f}, {k2:.4f}"],
            ["largest camera shift from GNSS (m)", f"{np.nanmax(adj.position_shift_m):.2f}"
             if np.isfinite(adj.position_shift_m).any() else "-"]]


def write_photo_run(photo_map: PhotoMap, out: str | Path, title: str) -> dict[str, Path]:
    """Write the run directory (see the module docstring); returns the report's paths."""
    out = Path(out)
    plots = out / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    folder, cols = photo_map.folder, photo_map.columns
    photo_map.map.save(out / "map.ot")
    photo_map.map.export_bt(out / "map.bt")
    write_run_frame(out, folder.origin)
    lat, lon, alt = folder.origin.to_geodetic(*photo_map.cameras.T)
    with open(out / "cameras.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["photo", "x", "y", "z", "lat", "lon", "alt"])
        for meta, p, la, lo, al in zip(folder.photos, photo_map.cameras, lat, lon, alt):
            w.writerow([meta.path.name, *(f"{v:.3f}" for v in p), f"{la:.8f}", f"{lo:.8f}", f"{al:.2f}"])
    rows = pair_rows(photo_map.pairs, folder)
    with open(out / "pairs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["ref"])
        w.writeheader()
        w.writerows(rows)
    layers = compute_layers(cols, LayerContext(now=float(len(folder.photos)), home=(0.0, 0.0)), ["fringe", "time",
                            "distance", "elevation"], photo_map.map)
    pictures = render(layers, plots / "layers", title=title)
    report = Report(title)
    report.heading("Photos")
    report.table(["setting", "value"], [["photos used", len(folder.photos)], ["skipped", len(folder.skipped)],
                                        ["origin (lat, lon, alt)", f"{folder.origin.lat:.7f}, {folder.origin.lon:.7f}, "
                                         f"{folder.origin.alt:.2f}"],
                                        ["pairs", len(rows)], ["pairs accepted", sum(p.accepted for p in photo_map.pairs)],
                                        ["voxel size (m)", photo_map.map.resolution]])
    if folder.skipped:
        report.table(["skipped photo", "why"], [[k, v] for k, v in folder.skipped.items()])
    if (adj := photo_map.adjustment) is not None:
        report.heading("Bundle adjustment")
        report.table(["quantity", "value"], adjustment_rows(adj))
    report.heading("Pairs")
    report.table(list(rows[0]) if rows else ["pairs"], [list(r.values()) for r in rows])
    report.heading("Camera positions over the color layer")
    report.image(plot_flight_path(cols, photo_map.cameras[:, :2], np.ones(cols.geometry.shape, bool),
                                  plots / "cameras.png", title), "camera positions (photo order) over the color layer")
    report.heading("Layers")
    for path in pictures:
        report.image(path, path.stem)
    metrics = {"final": {"photos": len(folder.photos), "pairs": len(rows),
                         "accepted": sum(p.accepted for p in photo_map.pairs),
                         "observed_columns": int(cols.observed.sum())},
               "settings": {"skipped": folder.skipped, "pairs": rows,
                            "adjustment": dict(adjustment_rows(photo_map.adjustment)) if photo_map.adjustment else None}}
    photo_map.paths = report.write(out, metrics)
    return photo_map.paths
