"""Pictures of layers and of a decision (A0..A3 with the waypoint), like the figures of a paper.

matplotlib with the Agg backend (no display needed). ``render`` writes one PNG per image
and an ``overview.png`` panel; reports call the same function.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from layerpilot.layers.feature_layers import FeatureLayers

if TYPE_CHECKING:
    from layerpilot.decide.decision import Decision

TITLES = {
    "color": "Color of the top voxel",
    "elevation_m": "Elevation: top of the highest occupied voxel",
    "fringe": "Fringe: edge of the known map",
    "time": "Time since last seen (scaled)",
    "distance": "Minimum observed distance / 100 m",
    "elevation": "Elevation (scaled)",
    "A0": "A0 = sum of w_i F_i",
    "A1": "A1 = Z A0 (area of interest)",
    "A2": "A2 = P A1 (distance ring)",
    "A3": "A3 = H A2 (path history): the score",
    "Z": "Z: area of interest",
    "P": "P: distance preference",
    "H": "H: path history",
}


def _images(layers: FeatureLayers, decision: Decision | None) -> list[tuple[str, np.ndarray, dict]]:
    images: list[tuple[str, np.ndarray, dict]] = [("color", np.where(layers.observed[..., None], layers.color, 1.0), {})]
    images.append(("elevation_m", np.ma.masked_invalid(layers.elevation_m),
                   {"cmap": "terrain", "label": "top of highest occupied voxel (m)"}))
    for name, image in layers.layers.items():
        images.append((name, image, {"cmap": "viridis", "vmin": 0.0, "vmax": 1.0, "label": "value"}))
    if decision is not None and decision.intermediates:
        for name in ("Z", "P", "H", "A0", "A1", "A2", "A3"):
            image = decision.intermediates[name]
            top = max(float(image.max()), 1e-6) if name.startswith("A") else 1.0
            images.append((name, image, {"cmap": "magma" if name.startswith("A") else "cividis",
                                         "vmin": 0.0, "vmax": top, "label": "score" if name[0] == "A" else "value"}))
    return images


def _draw(ax, fig, name: str, image: np.ndarray, opts: dict, layers: FeatureLayers,
          decision: Decision | None, position: tuple[float, ...] | None) -> None:
    opts = dict(opts)
    label = opts.pop("label", None)
    shown = ax.imshow(image, origin="lower", extent=layers.geometry.extent, interpolation="nearest", **opts)
    if label:
        fig.colorbar(shown, ax=ax, label=label, fraction=0.046, pad=0.04)
    if decision is not None and decision.intermediates and name != "Z":
        g = layers.geometry
        x, y = g.cell_centers()
        ax.contour(x, y, decision.intermediates["Z"], levels=[0.5], colors="white", linewidths=0.8, linestyles="--")
    if position is not None:
        ax.plot(position[0], position[1], marker="^", color="cyan", markeredgecolor="black", markersize=9,
                linestyle="none", label="drone")
    if decision is not None:
        if decision.runner_up is not None:
            rx, ry, _ = decision.runner_up.waypoint
            ax.plot(rx, ry, marker="X", color="white", markeredgecolor="black", markersize=9, linestyle="none",
                    label=f"runner-up {decision.runner_up.score:.3f}")
        wx, wy, _ = decision.waypoint
        ax.plot(wx, wy, marker="*", color="red", markeredgecolor="white", markersize=16, linestyle="none",
                label=f"waypoint {decision.score:.3f}" + (f" ({decision.fallback})" if decision.fallback else ""))
        ax.legend(loc="upper right", fontsize=7, framealpha=0.7)
    ax.set_title(TITLES.get(name, name.replace("_", " ").capitalize()), fontsize=10)
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")


def render(
    layers: FeatureLayers,
    out_dir: str | Path,
    decision: Decision | None = None,
    position: tuple[float, ...] | None = None,
    title: str = "",
    dpi: int = 100,
) -> list[Path]:
    """Write ``<name>.png`` for every layer (and Z, P, H, A0..A3 if the decision has them) and ``overview.png``.

    The waypoint (red star), runner-up (white X), drone (cyan triangle) and the area of
    interest's outline are drawn on every image. Returns the written paths.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    images = _images(layers, decision)
    written = []
    for name, image, opts in images:
        fig, ax = plt.subplots(figsize=(6.4, 5.6))
        _draw(ax, fig, name, image, opts, layers, decision, position)
        if title:
            fig.suptitle(title, fontsize=9)
        path = out / f"{name}.png"
        fig.savefig(path, dpi=dpi, bbox_inches="tight")
        plt.close(fig)
        written.append(path)
    cols = 4
    rows = -(-len(images) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 4.0 * rows), squeeze=False)
    for ax, (name, image, opts) in zip(axes.flat, images):
        _draw(ax, fig, name, image, opts, layers, decision, position)
    for ax in axes.flat[len(images):]:
        ax.axis("off")
    if decision is not None:
        title = (title + "\n" if title else "") + decision.explain()
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = out / "overview.png"
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    written.append(path)
    return written
