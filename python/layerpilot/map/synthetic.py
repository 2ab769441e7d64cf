"""Deterministic depth-camera frames over rough terrain with trees, for benchmarks and tests.

A heightfield (rolling hills plus tree crowns as bumps) is ray-marched from a 640x480 camera
flying 40-60 m above it, pitched down (60 degrees, the simulator's default), so frames look like a survey drone's: most rays hit
ground 50-100 m away, some leave the 100 m range.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Frame:
    points: np.ndarray  # float32 (N, 3), map frame; NaN where the ray hit nothing
    colors: np.ndarray  # uint8 (N, 3)
    origin: np.ndarray  # float64 (3,)
    stamp: float


class Heightfield:
    """Terrain + trees sampled on a 0.25 m grid, bilinear in between."""

    def __init__(self, seed: int = 0, size: float = 600.0, cell: float = 0.25, trees: int = 1500) -> None:
        rng = np.random.default_rng(seed)
        self.size, self.cell = size, cell
        n = int(size / cell)
        coords = (np.arange(n) + 0.5) * cell - size / 2
        x, y = np.meshgrid(coords, coords)
        h = np.zeros_like(x)
        for _ in range(6):  # hills of tens of metres
            k = rng.uniform(0.005, 0.03, 2)
            h += rng.uniform(2, 8) * np.sin(k[0] * x + rng.uniform(0, 6)) * np.cos(k[1] * y + rng.uniform(0, 6))
        for tx, ty, r, th in zip(*(rng.uniform(-size / 2, size / 2, trees) for _ in range(2)),
                                 rng.uniform(2, 5, trees), rng.uniform(8, 20, trees)):
            i0, i1 = int((ty - r + size / 2) / cell), int((ty + r + size / 2) / cell) + 1
            j0, j1 = int((tx - r + size / 2) / cell), int((tx + r + size / 2) / cell) + 1
            i0, j0, i1, j1 = max(i0, 0), max(j0, 0), min(i1, n), min(j1, n)
            d2 = ((x[i0:i1, j0:j1] - tx) ** 2 + (y[i0:i1, j0:j1] - ty) ** 2) / r**2
            bump = np.where(d2 < 1, th * np.sqrt(np.clip(1 - d2, 0, 1)), 0)
            h[i0:i1, j0:j1] = np.maximum(h[i0:i1, j0:j1], bump + h[i0:i1, j0:j1].min())
        self.h = h.astype(np.float32)
        self.tree_mask = (h - h.min()) > 0

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        n = self.h.shape[0]
        fx = np.clip((x + self.size / 2) / self.cell - 0.5, 0, n - 1.001)
        fy = np.clip((y + self.size / 2) / self.cell - 0.5, 0, n - 1.001)
        i, j = fy.astype(np.int32), fx.astype(np.int32)
        ty, tx = fy - i, fx - j
        h = self.h
        return ((h[i, j] * (1 - tx) + h[i, j + 1] * tx) * (1 - ty) + (h[i + 1, j] * (1 - tx) + h[i + 1, j + 1] * tx) * ty)


def camera_rays(width: int, height: int, hfov_deg: float, yaw: float, pitch_deg: float) -> np.ndarray:
    """Unit ray directions (H*W, 3) in the map frame for a camera yawed and pitched down."""
    f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
    u, v = np.meshgrid(np.arange(width) + 0.5 - width / 2, np.arange(height) + 0.5 - height / 2)
    # camera: forward, left, up in the body frame before pitch
    d = np.stack([np.full_like(u, f), -u, -v], axis=-1).reshape(-1, 3)
    p = np.radians(pitch_deg)
    pitch = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    rot = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    d = d @ (rot @ pitch).T
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def survey_frames(count: int, seed: int = 0, width: int = 640, height: int = 480,
                  pitch_deg: float = 60.0, max_distance: float = 130.0) -> list[Frame]:
    """``count`` frames along a straight survey leg at 40-60 m, camera pitched down (degrees)."""
    field = Heightfield(seed)
    rng = np.random.default_rng(seed + 1)
    frames = []
    for k in range(count):
        x, y = -100.0 + 15.0 * k, rng.uniform(-20, 20)
        z = float(field.height(np.array([x]), np.array([y]))[0]) + rng.uniform(40, 60)
        origin = np.array([x, y, z])
        dirs = camera_rays(width, height, 90.0, yaw=rng.uniform(-0.3, 0.3), pitch_deg=pitch_deg)
        t = np.full(len(dirs), np.nan)
        prev = np.zeros(len(dirs))
        for step in np.arange(1.0, max_distance, 1.0):
            todo = np.isnan(t)
            p = origin + dirs[todo] * step
            below = p[:, 2] < field.height(p[:, 0], p[:, 1])
            idx = np.flatnonzero(todo)[below]
            t[idx] = step
            prev[np.flatnonzero(todo)[~below]] = step
        hit = ~np.isnan(t)
        lo, hi = prev[hit], t[hit]
        for _ in range(10):  # bisection to millimetres
            mid = 0.5 * (lo + hi)
            p = origin + dirs[hit] * mid[:, None]
            below = p[:, 2] < field.height(p[:, 0], p[:, 1])
            hi, lo = np.where(below, mid, hi), np.where(below, lo, mid)
        t[hit] = hi
        pts = (origin + dirs * t[:, None]).astype(np.float32)
        grass = np.array([70, 120, 50]) + rng.integers(-20, 20, (len(pts), 3))
        colors = np.clip(grass, 0, 255).astype(np.uint8)
        frames.append(Frame(pts, colors, origin, float(k)))
    return frames
