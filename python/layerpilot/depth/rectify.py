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
    colors: np.ndarray  # uint8 (H, W, 3): the reference image's colour at each canonical pixel (nearest)
    vertical: bool  # stereoRectify chose a vertical pair
    mirrored: bool


def _grey(frame: CameraFrame, scale: float) -> np.ndarray:
    grey = cv2.cvtColor(frame.image, cv2.COLOR_RGB2GRAY)
    return grey if scale == 1.0 else cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


def _intrinsics(frame: CameraFrame, scale: float) -> tuple[np.ndarray, tuple[int, int]]:
    """K and image size (w, h) at ``scale`` (cv2.resize's size for ``fx = fy = scale``: rounded half to even)."""
    if scale == 1.0:
        return frame.intrinsics.K, frame.size
    w, h = frame.size
    return frame.intrinsics.scaled(scale).K, (round(w * scale), round(h * scale))  # pixel centres keep their place


def _view(frame: CameraFrame, scale: float, K: np.ndarray, R: np.ndarray, P: np.ndarray, size: tuple[int, int],
          colors: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """One view in the rectified layout: its grey image, its valid mask (uint8, 255 = inside the frame) and,
    if ``colors``, the frame's colour at the nearest full-resolution pixel."""
    mx, my = cv2.initUndistortRectifyMap(K, None, R, P, size, cv2.CV_32FC1)
    grey = cv2.remap(_grey(frame, scale), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    valid = cv2.inRange(mx, 0, size[0] - 1) & cv2.inRange(my, 0, size[1] - 1)
    # remap's nearest rounds half to even and its replicated border clamps, as rint and clip would
    rgb = cv2.remap(frame.image, (mx + 0.5) / scale - 0.5, (my + 0.5) / scale - 0.5, cv2.INTER_NEAREST,
                    borderMode=cv2.BORDER_REPLICATE) if colors else None
    return grey, valid, rgb


def rectify(ref: CameraFrame, other: CameraFrame, scale: float = 1.0) -> RectifiedPair:
    """Rectify ``ref`` (the frame whose view the points will come from) against ``other``."""
    if ref.size != other.size:
        raise ValueError(f"other: image size {other.size} differs from ref {ref.size}")
    K_r, size = _intrinsics(ref, scale)
    K_o, _ = _intrinsics(other, scale)
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
    left, left_valid, colors = (_canonical(a, vertical, mirrored) for a in _view(ref, scale, K_r, R1, P1, size, True))
    right, right_valid = (_canonical(a, vertical, mirrored) for a in _view(other, scale, K_o, R2, P2, size, False)[:2])
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
    return RectifiedPair(left, right, left_valid > 0, right_valid > 0, f, cx, cy, float(abs(other_pos)), to_camera,
                         colors, vertical, mirrored)


def _canonical(image: np.ndarray, vertical: bool, mirrored: bool) -> np.ndarray:
    """A rectified image in the canonical layout: remapping first and transposing / mirroring the result
    is per pixel the same as remapping with transposed / mirrored maps, without copying the float maps."""
    image = cv2.transpose(image) if vertical else image
    return cv2.flip(image, 1) if mirrored else image


def _zoomed(P: np.ndarray, s: float, size: tuple[int, int]) -> np.ndarray:
    """Projection matrix ``P`` with its focal length scaled by ``s`` about the image centre."""
    cx, cy = (size[0] - 1) / 2, (size[1] - 1) / 2
    return np.array([[s, 0.0, (1 - s) * cx], [0.0, s, (1 - s) * cy], [0.0, 0.0, 1.0]]) @ P
