"""`layerpilot bench photos`: stereo from real photos against a reference surface, adjusted vs refined vs raw poses.

For every pair the picker takes: the share of triangulated points within 0.5 m and 1 m of the
reference surface (points over it only), the coverage of the pair's overlap and the rotation
correction; then the map's elevation layer against the reference (median and 90th percentile
absolute difference over the columns both cover). The same flight runs three times in one process:
with bundle-adjusted poses, with per-pair refined relative poses and with the raw GNSS/attitude
poses. The reference is read for scoring only; nothing of it reaches the pipeline. JSON line last.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

from layerpilot.eval.photo_run import adjustment_rows, build_photo_map
from layerpilot.eval.surface import read_reference, score_elevation, score_points
from layerpilot.photos import PhotoConfig, read_folder
from layerpilot.photos.config import POSES

SHARED = Path("..") / "shared" / "data" / "brighton_beach"  # beside the project: from its root, or the checkout's


def shared_photos() -> Path:
    """The shared Brighton Beach survey: ``../shared/data/brighton_beach`` from the working directory (any install),
    else beside the source checkout (an editable install); ValueError naming the flags when neither holds it."""
    here = [Path.cwd() / SHARED, Path(__file__).resolve().parents[3] / SHARED]
    for data in here:
        if (data / "images").is_dir():
            return data
    raise ValueError(f"no default photo folder: pass --folder DIR and --reference FILE "
                     f"(looked for images/ in {', '.join(str(d.resolve()) for d in here)})")


def _fmt(v: float, spec: str = ".3f") -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def _no_nan(value):
    """NaN (no pair, no point) as JSON null."""
    if isinstance(value, dict):
        return {k: _no_nan(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_no_nan(v) for v in value]
    return None if isinstance(value, float) and math.isnan(value) else value


def run(folder_path: Path, reference_path: Path, width: int) -> dict:
    folder = read_folder(folder_path, width=width)
    t0 = time.monotonic()
    surface = read_reference(reference_path, folder.origin)
    print(f"reference {reference_path.name}: its CRS -> WGS 84 -> map frame at {folder.origin.lat:.6f}, "
          f"{folder.origin.lon:.6f}, {folder.origin.alt:.2f} m (geodesy.LocalFrame), heights unchanged; "
          f"{time.monotonic() - t0:.1f} s")
    out: dict = {"photos": len(folder.photos), "skipped": len(folder.skipped), "width": width}
    for name in POSES:
        t0 = time.monotonic()
        result = build_photo_map(folder, replace(PhotoConfig(width=width), poses=name), label=name)
        rows = []
        for p in result.pairs:
            s = score_points(surface, p.cloud.points) if p.cloud is not None else None
            r = p.refinement
            rows.append({"pair": f"{folder.photos[p.ref].path.stem}-{folder.photos[p.partner].path.stem}",
                         "result": p.reason, "inliers": r.inliers if r else None,
                         "rotation_correction_deg": r.rotation_correction_deg if r else None,
                         "points": len(p.cloud) if p.cloud is not None else 0,
                         "scored": s.scored if s else 0, "within_0_5m": s.within_half if s else math.nan,
                         "within_1m": s.within_1m if s else math.nan, "overlap_coverage": p.coverage})
        cols = result.columns
        elev = score_elevation(surface, cols.elevation, cols.geometry)
        scored = sum(r["scored"] for r in rows)
        pooled = {k: (sum(r[k] * r["scored"] for r in rows if r["scored"]) / scored if scored else math.nan)
                  for k in ("within_0_5m", "within_1m")}
        out[name] = {"pairs": len(rows), "accepted": sum(r["points"] > 0 for r in rows), "scored_points": scored,
                     **pooled, "elevation_columns": elev.columns, "elevation_median_m": elev.median,
                     "elevation_p90_m": elev.p90, "wall_s": round(time.monotonic() - t0, 1), "per_pair": rows}
        print(f"\n{name} poses: {len(rows)} pairs, {out[name]['accepted']} accepted, {result.map.resolution} m voxels")
        if result.adjustment is not None:
            adj = dict(adjustment_rows(result.adjustment))
            out[name]["adjustment"] = adj
            print("; ".join(f"{k}: {v}" for k, v in adj.items()))
        print(f"{'pair':<20}{'result':<20}{'inliers':>8}{'rot corr':>9}{'points':>8}{'scored':>8}"
              f"{'<=0.5m':>8}{'<=1m':>8}{'cover':>7}")
        for r in rows:
            print(f"{r['pair']:<20}{r['result']:<20}{_fmt(r['inliers'], 'd'):>8}"
                  f"{_fmt(r['rotation_correction_deg'], '.2f'):>9}{r['points']:>8}{r['scored']:>8}"
                  f"{_fmt(r['within_0_5m']):>8}{_fmt(r['within_1m']):>8}{_fmt(r['overlap_coverage'], '.2f'):>7}")
        print(f"pooled: {_fmt(pooled['within_0_5m'])} within 0.5 m, {_fmt(pooled['within_1m'])} within 1 m of "
              f"{scored} scored points; elevation layer vs reference over {elev.columns} columns: median "
              f"{_fmt(elev.median, '.2f')} m, p90 {_fmt(elev.p90, '.2f')} m")
    return out


def main(folder: Path | None, reference: Path | None, width: int) -> int:
    if folder is None or reference is None:
        data = shared_photos()
        folder, reference = folder or data / "images", reference or data / "model.laz"
    out = run(folder, reference, width)
    print(f"\n{' / '.join(POSES)}: within 1 m " + " / ".join(_fmt(out[k]['within_1m']) for k in POSES)
          + ", elevation median " + " / ".join(_fmt(out[k]['elevation_median_m'], '.2f') for k in POSES)
          + " m (targets: >= 0.9 within 1 m, median < 0.5 m)")
    json.dump(_no_nan(out), sys.stdout)
    sys.stdout.write("\n")
    return 0
