"""`layerpilot depth preview`: a PNG panel of one rendered pair, to see what the matcher does."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from layerpilot.depth.config import preset_for
from layerpilot.depth.evaluate import score
from layerpilot.depth.stereo import StereoMatcher
from layerpilot.eval.fixtures import BENCH_PAIRS, render_pair


def write_preview(out: Path, width: int = 640, height: int = 480, index: int = 0, seed: int = 0) -> dict:
    """Left/right rectified, disparity, estimated depth, true depth and relative error of pair ``index``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from layerpilot.camera import CameraConfig
    from layerpilot.sim import Renderer, World, WorldConfig

    if not 0 <= index < len(BENCH_PAIRS):
        raise ValueError(f"index: pair {index} does not exist (0..{len(BENCH_PAIRS) - 1})")
    config = preset_for(width)
    spec = dataclasses.replace(BENCH_PAIRS[index], ratio=config.pick.target_baseline_ratio)
    with Renderer(World(WorldConfig(seed=seed)), CameraConfig(width=width, height=height)) as r:
        ref, other = render_pair(r, spec)
    cloud, disp = StereoMatcher(config.match).cloud(ref, other)
    s = score(cloud, ref, scale=config.match.scale)
    uv, z = ref.project(cloud.points.astype(np.float64))
    estimated = _on_matching_grid(uv, z, ref.depth.shape, config.match.scale)
    error = _on_matching_grid(uv, np.minimum(s.rel_errors, 1.0), ref.depth.shape, config.match.scale)
    truth = np.where(ref.depth < 100.0, ref.depth, np.nan)
    vmax = float(np.nanmax(truth)) if np.isfinite(truth).any() else 100.0
    panels = [("left rectified (reference)", disp.pair.left, "gray", None),
              ("right rectified (partner)", disp.pair.right, "gray", None),
              ("disparity [px]", disp.disparity, "viridis", None),
              ("estimated depth [m]", estimated, "magma", (0, vmax)),
              ("true depth [m]", truth, "magma", (0, vmax)),
              ("|rel. error| (red > 5%)", error, "RdYlGn_r", (0, 0.1))]
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5))
    for ax, (title, img, cmap, lim) in zip(axes.flat, panels):
        im = ax.imshow(img, cmap=cmap, vmin=None if lim is None else lim[0], vmax=None if lim is None else lim[1])
        ax.set_title(title)
        ax.axis("off")
        if cmap != "gray":
            fig.colorbar(im, ax=ax, fraction=0.035)
    fig.suptitle(f"pair {index}: altitude {spec.altitude:.0f} m, pitch {spec.pitch_deg:.0f} deg, "
                 f"{width}x{height}; precision {s.precision:.3f}, coverage {s.coverage:.3f}, "
                 f"median |rel err| {s.median_rel_error:.4f}")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=80)
    plt.close(fig)
    return {"precision": s.precision, "coverage": s.coverage, "median_rel_error": s.median_rel_error}


def _on_matching_grid(uv: np.ndarray, values: np.ndarray, shape: tuple[int, int], scale: float) -> np.ndarray:
    """Per-point values drawn one cell per matching pixel, shown at full size (no dotted pattern)."""
    import cv2

    h, w = shape
    gh, gw = max(1, round(h * scale)), max(1, round(w * scale))
    grid = np.full((gh, gw), np.nan, np.float32)
    gx = np.clip(((uv[:, 0] + 0.5) * scale).astype(int), 0, gw - 1)
    gy = np.clip(((uv[:, 1] + 0.5) * scale).astype(int), 0, gh - 1)
    grid[gy, gx] = values
    return cv2.resize(grid, (w, h), interpolation=cv2.INTER_NEAREST)
