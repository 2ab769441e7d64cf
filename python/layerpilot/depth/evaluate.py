"""Score a point cloud against the true depth image of the frame it was seen from."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from layerpilot.geometry import CameraFrame, PointCloud


@dataclass(frozen=True)
class Score:
    points: int
    precision: float  # fraction of points within ``tolerance`` relative error of the true depth
    coverage: float  # fraction of true-depth pixels (< max_depth) that yielded a point
    median_rel_error: float
    rel_errors: np.ndarray  # per point; inf where the true depth is missing (sky)


def score(cloud: PointCloud, frame: CameraFrame, scale: float = 1.0, tolerance: float = 0.05,
          max_depth: float = 100.0) -> Score:
    """Coverage is counted on the matching grid (``scale`` of the image): one point per cell."""
    if frame.depth is None:
        raise ValueError("frame: has no true depth")
    h, w = frame.depth.shape
    uv, z = frame.project(cloud.points.astype(np.float64))
    px = np.clip(np.rint(uv[:, 0]).astype(np.int64), 0, w - 1)
    py = np.clip(np.rint(uv[:, 1]).astype(np.int64), 0, h - 1)
    truth = frame.depth[py, px].astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(np.isfinite(truth) & (truth > 0), np.abs(z - truth) / truth, np.inf)
    gw, gh = max(1, round(w * scale)), max(1, round(h * scale))
    grid_truth = cv2.resize(frame.depth, (gw, gh), interpolation=cv2.INTER_NEAREST)
    wanted = np.isfinite(grid_truth) & (grid_truth < max_depth)
    covered = np.zeros((gh, gw), bool)
    gx = np.clip(((uv[:, 0] + 0.5) * scale).astype(np.int64), 0, gw - 1)
    gy = np.clip(((uv[:, 1] + 0.5) * scale).astype(np.int64), 0, gh - 1)
    covered[gy, gx] = True
    n = len(rel)
    return Score(n, float((rel <= tolerance).mean()) if n else float("nan"),
                 float((covered & wanted).sum() / max(1, wanted.sum())),
                 float(np.median(rel)) if n else float("nan"), rel)
