"""Figures for reports: metrics over time, flight path over the color layer, layer images.

matplotlib's Agg backend only (no display); every function writes one PNG and returns its path.
"""

from __future__ import annotations

import itertools
import os
import warnings
from pathlib import Path
from typing import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from layerpilot.eval.series import MetricSeries  # noqa: E402
from layerpilot.map.columns import ColumnLayers  # noqa: E402

PATH_COLORS = ["red", "cyan", "magenta", "orange", "lime"]  # a fleet's drones, in mission order
LABELS = {
    "percent_mapped": "area mapped (%)",
    "avg_time_since_observed": "average time since observed (s)",
    "avg_min_distance": "average minimum observed distance (m)",
    "paper_recall": "3D recall (paper)",
    "paper_mse": "3D MSE (paper, m)",
    "precision": "3D precision",
    "recall": "3D recall (completeness)",
    "f_score": "3D F-score",
}


def _save(fig: plt.Figure, path: str | os.PathLike) -> Path:
    path = Path(path)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_metric(runs: Mapping[str, Sequence[MetricSeries]], metric: str | Mapping[str, str],
                path: str | os.PathLike, ylabel: str | None = None) -> Path:
    """A metric over time, one line per label (mean over its runs, min-max band if several).

    ``metric``: a column, or {line name: column} to draw several columns of each label on one plot
    (a metric beside its absolute twin, the offset's three axes)."""
    if not runs:
        raise ValueError("runs: nothing to plot")
    columns = {"": metric} if isinstance(metric, str) else dict(metric)
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, series in runs.items():
        if not series:
            raise ValueError(f"runs: {label!r} has no series")
        n = min(len(s) for s in series)
        t = series[0].column("t")[:n]
        for line, column in columns.items():
            values = np.array([s.column(column)[:n] for s in series])
            with warnings.catch_warnings():  # all-NaN samples (nothing mapped yet) stay NaN, silently
                warnings.simplefilter("ignore", RuntimeWarning)
                low, mean, high = np.nanmin(values, 0), np.nanmean(values, 0), np.nanmax(values, 0)
            name = line if len(runs) == 1 and line else f"{label}: {line}" if line else label
            (drawn,) = ax.plot(t, mean, label=name)
            if len(series) > 1:
                ax.fill_between(t, low, high, color=drawn.get_color(), alpha=0.2)
    first = next(iter(columns.values()))
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel(ylabel or LABELS.get(first, first))
    ax.grid(alpha=0.3)
    if len(runs) * len(columns) > 1:
        ax.legend(fontsize="small")
    return _save(fig, path)


def plot_flight_path(
    layers: ColumnLayers,
    path_xy: np.ndarray | Mapping[str, np.ndarray],
    aoi: np.ndarray,
    out: str | os.PathLike,
    title: str = "",
) -> Path:
    """The flight path (x, y per row) drawn over the color layer, with the area of interest outlined;
    a fleet's paths (vehicle -> path) one colour each, named in the legend."""
    paths = {name: np.asarray(p, dtype=np.float64) for name, p in
             (path_xy.items() if isinstance(path_xy, Mapping) else [("", path_xy)])}
    for name, p in paths.items():
        if p.ndim != 2 or p.shape[1] != 2:
            raise ValueError(f"path_xy{f'[{name!r}]' if name else ''}: expected shape (N, 2), got {p.shape}")
    if aoi.shape != layers.geometry.shape:
        raise ValueError(f"aoi: expected shape {layers.geometry.shape}, got {aoi.shape}")
    g = layers.geometry
    image = layers.color.copy()
    image[~layers.observed] = 40  # unobserved columns dark grey
    fig, ax = plt.subplots(figsize=(6, 6))
    ax.imshow(image, origin="lower", extent=g.extent, interpolation="nearest")
    xs, ys = g.cell_centers()
    ax.contour(xs, ys, aoi.astype(float), levels=[0.5], colors="yellow", linewidths=1.2)
    drawn = False
    for (name, p), color in zip(paths.items(), itertools.cycle(PATH_COLORS)):
        if not len(p):
            continue
        ax.plot(p[:, 0], p[:, 1], color=color, linewidth=1.0, label=name or None)
        ax.plot(*p[0], "o", color="white", markeredgecolor="black", label=None if drawn else "start")
        ax.plot(*p[-1], "s", color=color, markeredgecolor="black", label=None if drawn else "end")
        drawn = True
    if drawn:
        ax.legend(fontsize="small", loc="upper right")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    if title:
        ax.set_title(title)
    return _save(fig, out)


def plot_layer(
    values: np.ndarray, layers: ColumnLayers, out: str | os.PathLike, title: str, cmap: str = "viridis"
) -> Path:
    """A scalar layer on the layers' grid with a colorbar; NaN cells stay blank."""
    if values.shape != layers.geometry.shape:
        raise ValueError(f"values: expected shape {layers.geometry.shape}, got {values.shape}")
    fig, ax = plt.subplots(figsize=(6, 5))
    im = ax.imshow(values, origin="lower", extent=layers.geometry.extent, cmap=cmap, interpolation="nearest")
    fig.colorbar(im, ax=ax, shrink=0.8)
    ax.set_title(title)
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    return _save(fig, out)
