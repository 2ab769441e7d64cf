"""Exact synthetic views: a noise-textured ground plane seen through plane-induced homographies.

Used by the geometry tests: the depth of every pixel is known in closed form,
so the stereo chain must return the plane at its true distance.
"""

from __future__ import annotations

import cv2
import numpy as np

from layerpilot.depth.frames import Frame


def look_pose(center: np.ndarray, yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Map <- camera (OpenCV axes) for a camera heading ``yaw`` (from east, counter-clockwise)
    and looking ``pitch`` degrees below the horizon (90 = straight down)."""
    yaw, pitch = np.radians(yaw_deg), np.radians(pitch_deg)
    heading = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    z = np.cos(pitch) * heading + np.array([0.0, 0.0, -np.sin(pitch)])
    x = np.array([np.sin(yaw), -np.cos(yaw), 0.0])
    pose = np.eye(4)
    pose[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    pose[:3, 3] = center
    return pose


def intrinsics(width: int, height: int, hfov_deg: float = 60.0) -> np.ndarray:
    f = width / 2 / np.tan(np.radians(hfov_deg) / 2)
    return np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])


def noise_texture(size: int = 2048, seed: int = 0) -> np.ndarray:
    """RGB texture with detail at every scale down to ~2 texels (matchable at any distance)."""
    rng = np.random.default_rng(seed)
    tex = np.zeros((size, size), np.float32)
    for cells in (8, 32, 128, 512, size // 2):
        layer = rng.random((cells, cells), np.float32)
        tex += cv2.resize(layer, (size, size), interpolation=cv2.INTER_CUBIC)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    rgb = np.stack([tex, 0.6 * tex + 0.2, 1.0 - 0.5 * tex], axis=2)
    return (255 * rgb).astype(np.uint8)


def plane_frame(pose: np.ndarray, K: np.ndarray, size: tuple[int, int], texture: np.ndarray,
                extent: float, stamp: float = 0.0) -> Frame:
    """View of the plane z = 0 whose square [-extent/2, extent/2]^2 carries ``texture``."""
    w, h = size
    R, C = pose[:3, :3], pose[:3, 3]
    texel = extent / texture.shape[1]
    plane_from_tex = np.array([[texel, 0, -extent / 2 + texel / 2], [0, texel, -extent / 2 + texel / 2], [0, 0, 1]])
    cam_from_plane = np.column_stack([R.T[:, 0], R.T[:, 1], -R.T @ C])
    H = K @ cam_from_plane @ plane_from_tex
    image = cv2.warpPerspective(texture, H, (w, h), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_CONSTANT)
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u, float)], axis=-1) @ R.T
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = -C[2] / rays[..., 2]  # z-depth: the ray has unit camera-z
    depth = np.where(depth > 0, depth, np.inf).astype(np.float32)
    return Frame(image, pose, K, stamp, depth)
