"""The built-in feature layers: pure functions from column arrays to float32 images in [0, 1].

Higher means more interesting. Unobserved columns are 0 in every layer; the
functions never clip the area of interest (the fringe must see past it).
"""

from __future__ import annotations

import cv2
import numpy as np


def _check_mask(observed: np.ndarray) -> np.ndarray:
    if observed.ndim != 2 or observed.dtype != np.bool_:
        raise ValueError(f"observed: expected a 2D bool array, got {observed.shape} {observed.dtype}")
    return observed


def _check_like(name: str, arr: np.ndarray, observed: np.ndarray) -> None:
    if arr.shape[:2] != observed.shape:
        raise ValueError(f"{name}: expected shape {observed.shape}, got {arr.shape}")


def fringe(observed: np.ndarray, closing: int = 3) -> np.ndarray:
    """1 on the frontier (observed with an unobserved 8-neighbour), 1/d cells inside, 0 unobserved.

    d is the exact Euclidean distance (in cells) to the nearest unobserved column, so the
    first interior ring (d >= 2) gets at most 0.5 and deep interior tends to 0. A
    morphological closing with an elliptic ``closing`` x ``closing`` kernel first fills
    unobserved holes smaller than the kernel (they count as observed here), so the frontier
    is the true edge of the map and not every gap between trees. ``closing`` <= 1: no closing.
    A window with no unobserved column has no frontier: all 0.
    """
    mask = np.ascontiguousarray(_check_mask(observed)).view(np.uint8)
    if closing < 0:
        raise ValueError(f"closing: must be >= 0, got {closing}")
    if closing > 1:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (closing, closing))
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel)
    if not mask.any() or mask.all():
        return np.zeros(mask.shape, np.float32)
    dist = cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    with np.errstate(divide="ignore"):
        out = np.reciprocal(dist, out=dist)  # inf on unobserved cells (d = 0)
    out[out > 0.7] = 1.0  # d is exactly 1 or sqrt(2) on the frontier; every interior d >= 2
    out[mask == 0] = 0.0
    return out


def _scaled(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(v - min) / (max - min) over ``valid`` cells, 0 elsewhere and when all values are equal."""
    out = np.zeros(values.shape, np.float32)
    if not valid.any():
        return out
    lo = float(np.min(values, where=valid, initial=np.inf))
    hi = float(np.max(values, where=valid, initial=-np.inf))
    if hi > lo:
        np.subtract(values, lo, out=out, where=valid, casting="same_kind")
        out *= np.float32(1.0 / (hi - lo))
        np.minimum(out, 1.0, out=out)  # float32 rounding must not leave [0, 1]
    return out


def time_since_seen(observed: np.ndarray, last_seen: np.ndarray, now: float) -> np.ndarray:
    """Age (now - last seen) scaled over observed columns: oldest 1, freshest 0, all equal 0."""
    _check_like("last_seen", last_seen, _check_mask(observed))
    if not np.isfinite(now):
        raise ValueError(f"now: must be finite, got {now}")
    valid = observed & np.isfinite(last_seen)
    return _scaled(now - last_seen, valid)


def min_distance(observed: np.ndarray, distance: np.ndarray, max_distance: float = 100.0) -> np.ndarray:
    """Closest observation distance / ``max_distance``; farther than that counts as unobserved (0)."""
    _check_like("min_distance", distance, _check_mask(observed))
    if not max_distance > 0:
        raise ValueError(f"max_distance: must be > 0, got {max_distance}")
    seen = observed & (distance <= max_distance)
    return np.where(seen, distance / np.float32(max_distance), np.float32(0)).astype(np.float32, copy=False)


def elevation(observed: np.ndarray, top: np.ndarray) -> np.ndarray:
    """Top of the highest occupied voxel scaled over observed columns (lowest 0, highest 1)."""
    _check_like("elevation", top, _check_mask(observed))
    return _scaled(top, observed & np.isfinite(top))


def color(observed: np.ndarray, rgb: np.ndarray) -> np.ndarray:
    """The top voxel's RGB as float32 (h, w, 3) in [0, 1]; black where unobserved. For people only."""
    _check_like("color", rgb, _check_mask(observed))
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"color: expected (h, w, 3) uint8, got {rgb.shape} {rgb.dtype}")
    return np.where(observed[..., None], rgb.astype(np.float32) / 255.0, np.float32(0)).astype(np.float32)
