"""A picture of the simulator: camera view, its ground-truth depth, and a top-down map of the world."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from layerpilot.grid import GridGeometry
from layerpilot.camera import CameraConfig, camera_pose
from layerpilot.sim.world import World


def write_preview(world: World, camera: CameraConfig, x: float, y: float, height_above_ground: float,
                  yaw_deg: float, path: str | Path) -> dict:
    """Render from a vehicle at (x, y), ``height_above_ground`` over the terrain, and write a PNG.

    Returns numbers about the view (pixels of sky, depth range) for the caller to print.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from layerpilot.sim.render import Renderer

    z = float(world.terrain_height(x, y)) + height_above_ground
    pose = camera_pose((x, y, z), math.radians(yaw_deg), camera.pitch_deg)
    with Renderer(world, camera) as renderer:
        frame = renderer.render(pose)
        gl_renderer = renderer.renderer_name
    half = world.half
    res = max(world.config.size / 800.0, 0.5)
    n = int(round(world.config.size / res))
    top = world.surface_height(GridGeometry(-half, -half, res, n, n))

    fig, axes = plt.subplots(1, 3, figsize=(18, 5.4), constrained_layout=True)
    axes[0].imshow(frame.image)
    axes[0].set_title(f"camera {camera.width}x{camera.height}, {camera.hfov_deg:g} deg HFOV, "
                      f"pitch {camera.pitch_deg:g} deg down")
    finite = frame.depth[np.isfinite(frame.depth)]
    im = axes[1].imshow(np.where(np.isfinite(frame.depth), frame.depth, np.nan), cmap="viridis")
    fig.colorbar(im, ax=axes[1], label="z-depth (m), sky blank")
    axes[1].set_title("ground-truth depth")
    im = axes[2].imshow(top, origin="lower", extent=(-half, half, -half, half), cmap="terrain")
    fig.colorbar(im, ax=axes[2], label="surface height (m)")
    # where the optical axis and the image corners meet the ground (flat-ground sketch)
    K_inv = np.linalg.inv(frame.K)
    corners = np.array([[0, 0], [camera.width - 1, 0], [camera.width - 1, camera.height - 1], [0, camera.height - 1]])
    rays = (np.column_stack([corners, np.ones(4)]) @ K_inv.T) @ pose.rotation.T
    ground = float(world.terrain_height(x, y))
    t = np.where(rays[:, 2] < -1e-6, (ground - z) / np.minimum(rays[:, 2], -1e-6), 200.0)
    t = np.minimum(t, 4 * world.config.size)
    pts = pose.position[:2] + rays[:, :2] * t[:, None]
    axes[2].fill(pts[:, 0], pts[:, 1], facecolor="none", edgecolor="red", linewidth=1.5, label="view (flat ground)")
    axes[2].plot([x], [y], "r^", markersize=9, label="vehicle")
    axes[2].set_xlim(-half, half)
    axes[2].set_ylim(-half, half)
    axes[2].legend(loc="upper right", fontsize=8)
    axes[2].set_xlabel("x east (m)")
    axes[2].set_ylabel("y north (m)")
    stats = world.stats()
    axes[2].set_title(f"seed {world.config.seed}: {stats['trees']} trees, {stats['size_m']:g} m square")
    fig.suptitle(f"layerpilot sim preview - vehicle at ({x:g}, {y:g}) {height_above_ground:g} m above ground, "
                 f"yaw {yaw_deg:g} deg - {gl_renderer}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return {
        "path": str(path),
        "sky_fraction": float(np.mean(~np.isfinite(frame.depth))),
        "depth_min_m": float(finite.min()) if finite.size else math.inf,
        "depth_max_m": float(finite.max()) if finite.size else math.inf,
        "renderer": gl_renderer,
    }
