"""Rectification from the known relative pose of two frames.

``cv2.stereoRectify`` rotates both cameras so that epipolar lines become image
rows (sideways motion) or columns (motion along the image's vertical axis). The
rectified images are then transposed and/or mirrored into one canonical layout:
the reference frame is the *left* image of a horizontal pair, so the matcher
always sees positive disparities, ``Z = f * baseline / d``, and a canonical
camera point maps back to the reference camera through one rotation
(``to_camera``).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from layerpilot.geometry import CameraFrame


# alpha=0 keeps only pixels valid in both views. When rectification turns the views far (a
# baseline with a large part along the optical axis, as in forward flight with a tilted camera)
# that area is small and the crop zoomed in up to 9x: the disparities left the search range that
# the picker's baseline window assumes, and a third of the demo's pairs gave no points
# (docs/depth.md). Beyond MAX_ZOOM the focal length is scaled back about the image centre and the
# rectified border that falls outside a view is masked like any other invalid pixel.
MAX_ZOOM = 1.5


@dataclass(frozen=True)
class RectifiedPair:
    left: np.ndarray  # uint8 grey, canonical reference image
    right: np.ndarray  # uint8 grey, canonical partner image
    left_valid: np.ndarray  # bool, canonical pixel maps inside the reference image
    right_valid: np.ndarray
    f: float  # focal length in canonical pixels
    cx: float
    cy: float
    baseline: float  # metres
    to_camera: np.ndarray  # (3, 3) reference camera <- canonical rectified camera
    source_index: np.ndarray  # int32 (H, W): canonical pixel -> flat index of the nearest reference image pixel
    vertical: bool  # stereoRectify chose a vertical pair
    mirrored: bool


def _scaled(frame: CameraFrame, scale: float) -> tuple[np.ndarray, np.ndarray]:
    grey = cv2.cvtColor(frame.image, cv2.COLOR_RGB2GRAY)
    if scale == 1.0:
        return grey, frame.intrinsics.K
    grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return grey, frame.intrinsics.scaled(scale).K  # pixel centres, not corners, keep their place


def rectify(ref: CameraFrame, other: CameraFrame, scale: float = 1.0) -> RectifiedPair:
    """Rectify ``ref`` (the frame whose view the points will come from) against ``other``."""
    if ref.size != other.size:
        raise ValueError(f"other: image size {other.size} differs from ref {ref.size}")
    grey_r, K_r = _scaled(ref, scale)
    grey_o, K_o = _scaled(other, scale)
    size = (grey_r.shape[1], grey_r.shape[0])
    R = other.pose.rotation.T @ ref.pose.rotation  # x_other = R x_ref + T
    T = other.pose.rotation.T @ (ref.pose.position - other.pose.position)
    if np.linalg.norm(T) < 1e-9:
        raise ValueError("other: same camera centre as ref, no baseline")
    R1, R2, P1, P2, _, _, _ = cv2.stereoRectify(K_r, None, K_o, None, size, R, T.reshape(3, 1),
                                                flags=cv2.CALIB_ZERO_DISPARITY, alpha=0)
    zoom = P1[0, 0] / K_r[0, 0]
    if zoom > MAX_ZOOM:
        P1, P2 = (_zoomed(P, MAX_ZOOM / zoom, size) for P in (P1, P2))
    vertical = abs(P2[1, 3]) > abs(P2[0, 3])
    axis = 1 if vertical else 0
    other_pos = -P2[axis, 3] / P2[axis, axis]  # partner centre along the rectified baseline axis
    mirrored = other_pos < 0
    maps = []
    for K, Rr, P in ((K_r, R1, P1), (K_o, R2, P2)):
        mx, my = cv2.initUndistortRectifyMap(K, None, Rr, P, size, cv2.CV_32FC1)
        if vertical:
            mx, my = mx.T, my.T
        if mirrored:
            mx, my = mx[:, ::-1], my[:, ::-1]
        maps.append((np.ascontiguousarray(mx), np.ascontiguousarray(my)))
    (lx, ly), (rx, ry) = maps
    left = cv2.remap(grey_r, lx, ly, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    right = cv2.remap(grey_o, rx, ry, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    w, h = size
    f, cx, cy = float(P1[0, 0]), float(P1[0, 2]), float(P1[1, 2])
    M = np.eye(3)
    if vertical:
        cx, cy = cy, cx
        M = M[[1, 0, 2]]
    if mirrored:
        cx = left.shape[1] - 1 - cx
        M = np.diag([-1.0, 1.0, 1.0]) @ M
    # canonical point p_c = M @ p_rect and p_rect = R1 @ p_ref
    to_camera = R1.T @ M.T
    hh, ww = ref.image.shape[:2]  # full resolution
    px = np.clip(np.rint((lx + 0.5) / scale - 0.5), 0, ww - 1).astype(np.int32)
    py = np.clip(np.rint((ly + 0.5) / scale - 0.5), 0, hh - 1).astype(np.int32)
    return RectifiedPair(left, right, _inside(lx, ly, w, h), _inside(rx, ry, w, h), f, cx, cy,
                         float(abs(other_pos)), to_camera, py * np.int32(ww) + px, vertical, mirrored)


def _zoomed(P: np.ndarray, s: float, size: tuple[int, int]) -> np.ndarray:
    """Projection matrix ``P`` with its focal length scaled by ``s`` about the image centre."""
    cx, cy = (size[0] - 1) / 2, (size[1] - 1) / 2
    return np.array([[s, 0.0, (1 - s) * cx], [0.0, s, (1 - s) * cy], [0.0, 0.0, 1.0]]) @ P


def _inside(mx: np.ndarray, my: np.ndarray, w: int, h: int) -> np.ndarray:
    return (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
