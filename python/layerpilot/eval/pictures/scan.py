"""Build a map from a real laser scan and write it with pictures of its column layers."""

from __future__ import annotations

import bz2
from pathlib import Path

import numpy as np

from layerpilot.map.voxel_map import VoxelMap


def read_scan(path: Path) -> np.ndarray:
    """Points of a plain-text scan (one 'x y z' per line; .bz2 allowed) as float32 (N, 3)."""
    opener = bz2.open if path.suffix == ".bz2" else open
    with opener(path, "rt") as f:
        points = np.loadtxt(f, dtype=np.float32, ndmin=2)
    if points.shape[1] != 3:
        raise ValueError(f"{path}: expected 3 columns (x y z), got {points.shape[1]}")
    return points


def height_colors(points: np.ndarray) -> np.ndarray:
    """The scan has no camera: color points by height so the color layer shows something real."""
    import matplotlib

    z = points[:, 2]
    t = (z - np.percentile(z, 1)) / max(np.ptp(np.percentile(z, [1, 99])), 1e-6)
    return (matplotlib.colormaps["viridis"](np.clip(t, 0, 1))[:, :3] * 255).astype(np.uint8)


def build_scan_map(scan: Path, out: Path, resolution: float) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    points = read_scan(scan)
    m = VoxelMap(resolution)
    result = m.insert(points, np.zeros(3), height_colors(points), stamp=0.0, max_range=100.0)
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "map.ot", out / "map.bt"]
    m.save(written[0])
    m.export_bt(written[1])
    s = m.stats()
    lo, hi = np.array(s["bounds_min"]), np.array(s["bounds_max"])
    w, h = (np.ceil((hi[:2] - lo[:2]) / resolution)).astype(int) + 1
    cl = m.column_layers(lo[0], lo[1], int(w), int(h))
    extent = cl.geometry.extent
    for name, image, kwargs in (
        ("elevation", np.ma.masked_invalid(cl.elevation), {"cmap": "terrain"}),
        ("color", np.where(cl.observed[..., None], cl.color, 255), {}),
    ):
        fig, ax = plt.subplots(figsize=(8, 6))
        shown = ax.imshow(image, origin="lower", extent=extent, **kwargs)
        if name == "elevation":
            fig.colorbar(shown, ax=ax, label="top of highest occupied voxel (m)")
        ax.set(title=f"{name} layer: {scan.name}, {resolution} m voxels, {result.points_used} points",
               xlabel="x (m)", ylabel="y (m)")
        path = out / f"{name}.png"
        fig.savefig(path, dpi=100, bbox_inches="tight")
        plt.close(fig)
        written.append(path)
    return written
