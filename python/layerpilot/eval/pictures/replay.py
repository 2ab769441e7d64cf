"""The replay picture: the flown path and its waypoints vs another behavior's choices, over the map's layers.

Left: over the color layer (unobserved columns dark). Right: over the elevation layer. On both,
the flown path (red), the live pilot's waypoints (red squares) and, for each replayed tick, an
arrow from where the drone was to where the replayed behavior would have gone (cyan).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np

from layerpilot.eval.pictures.plots import _save, plt
from layerpilot.map.columns import ColumnLayers


def plot_replay(layers: ColumnLayers, path_xy: np.ndarray, flown: Sequence[dict], replayed: Sequence[dict],
                out: str | os.PathLike, title: str = "") -> Path:
    """``flown``/``replayed``: decision records with a ``waypoint``; replayed ones also carry ``position``."""
    path_xy = np.asarray(path_xy, np.float64).reshape(-1, 2)
    g = layers.geometry
    color = layers.color.copy()
    color[~layers.observed] = 40
    elevation = np.where(layers.observed, layers.elevation, np.nan)
    fig, axes = plt.subplots(1, 2, figsize=(12, 6))
    for ax, (image, name) in zip(axes, ((color, "color"), (elevation, "elevation (m)"))):
        im = ax.imshow(image, origin="lower", extent=g.extent, interpolation="nearest",
                       cmap=None if image.ndim == 3 else "terrain")
        if image.ndim == 2:
            fig.colorbar(im, ax=ax, shrink=0.7)
        if len(path_xy):
            ax.plot(path_xy[:, 0], path_xy[:, 1], color="red", linewidth=1.0, label="flown path")
        wps = np.array([d["waypoint"][:2] for d in flown]).reshape(-1, 2)
        if len(wps):
            ax.plot(wps[:, 0], wps[:, 1], "s", color="red", markeredgecolor="black", label="flown waypoints")
        chosen = [d for d in replayed if "waypoint" in d]
        for i, d in enumerate(chosen):
            (x0, y0), (x1, y1) = d["position"][:2], d["waypoint"][:2]
            ax.annotate("", (x1, y1), (x0, y0), arrowprops={"arrowstyle": "->", "color": "cyan", "lw": 0.8})
        if chosen:
            c = np.array([d["waypoint"][:2] for d in chosen])
            ax.plot(c[:, 0], c[:, 1], "o", color="cyan", markeredgecolor="black", markersize=4,
                    label="replayed choices")
        ax.set_title(name)
        ax.set_xlabel("x east (m)")
        ax.set_ylabel("y north (m)")
        ax.legend(fontsize="small", loc="upper right")
    if title:
        fig.suptitle(title)
    return _save(fig, out)
