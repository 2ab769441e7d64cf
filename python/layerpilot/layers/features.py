"""The built-in feature layers: pure functions from column arrays to float32 images in [0, 1].

Higher means more interesting. Unobserved columns are 0 in every layer; the
functions never clip the area of interest (the fringe must see past it).
"""

from __future__ import annotations

import threading

import numpy as np

from layerpilot.grid import GridWindow
from layerpilot.layers.distance import ClosedDistance
from layerpilot.map.columns import observed_range


def _check_mask(observed: np.ndarray) -> np.ndarray:
    if observed.ndim != 2 or observed.dtype != np.bool_:
        raise ValueError(f"observed: expected a 2D bool array, got {observed.shape} {observed.dtype}")
    return observed


def _check_like(name: str, arr: np.ndarray, observed: np.ndarray) -> None:
    if arr.shape[:2] != observed.shape:
        raise ValueError(f"{name}: expected shape {observed.shape}, got {arr.shape}")


def fringe(observed: np.ndarray, closing: int = 3, window: GridWindow | None = None) -> np.ndarray:
    """1 on the frontier (observed with an unobserved 8-neighbour), 1/d cells inside, 0 unobserved.

    d is the exact Euclidean distance (in cells) to the nearest unobserved column, so the
    first interior ring (d >= 2) gets at most 0.5 and deep interior tends to 0. A
    morphological closing with an elliptic ``closing`` x ``closing`` kernel first fills
    unobserved holes smaller than the kernel (they count as observed here), so the frontier
    is the true edge of the map and not every gap between trees. ``closing`` <= 1: no closing.
    A window with no unobserved column has no frontier: all 0.

    The distances are kept from call to call and redone only where the mask changed
    (``layers.distance``); ``window``: only those cells (an array of the window's shape).
    """
    _check_mask(observed)
    if closing < 0:
        raise ValueError(f"closing: must be >= 0, got {closing}")
    with _LOCK:
        tracker = _TRACKERS.setdefault(closing, ClosedDistance(closing))
    region = GridWindow(0, observed.shape[0], 0, observed.shape[1]) if window is None else window
    with tracker.lock:
        closed, dist = tracker.update(observed)
        if tracker.zeros in (0, closed.size):
            return np.zeros(region.shape, np.float32)
        d, mask = dist[region.slices].copy(), closed[region.slices].copy()
    with np.errstate(divide="ignore"):
        out = np.reciprocal(d, out=d)  # inf on unobserved cells (d = 0)
    out[out > 0.7] = 1.0  # d is exactly 1 or sqrt(2) on the frontier; every interior d >= 2
    out[mask == 0] = 0.0
    return out


_LOCK = threading.Lock()
_TRACKERS: dict[int, ClosedDistance] = {}  # per closing size: the last mask's distances, kept up to date


def _scaled(values: np.ndarray, valid: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """(v - lo) / (hi - lo) on ``valid`` cells, 0 elsewhere and when hi == lo."""
    out = np.zeros(values.shape, np.float32)
    if hi > lo:
        np.subtract(values, lo, out=out, where=valid, casting="same_kind")
        out *= np.float32(1.0 / (hi - lo))
        np.minimum(out, 1.0, out=out)  # float32 rounding must not leave [0, 1]
    return out


def _region(arr: np.ndarray, window: GridWindow | None) -> np.ndarray:
    return arr if window is None else arr[window.slices]


def time_since_seen(observed: np.ndarray, last_seen: np.ndarray, now: float,
                    window: GridWindow | None = None, span: tuple[float, float] | None = None) -> np.ndarray:
    """Age (now - last seen) scaled over observed columns: oldest 1, freshest 0, all equal 0.

    ``window``: only those cells, still scaled over the whole grid. ``span``: the whole
    grid's (oldest, newest) when ``last_seen`` holds values only near the drone
    (``ColumnLayers.value_range``); default: from the arrays.
    """
    _check_like("last_seen", last_seen, _check_mask(observed))
    if not np.isfinite(now):
        raise ValueError(f"now: must be finite, got {now}")
    seen = observed_range(last_seen, observed) if span is None else span
    last, obs = _region(last_seen, window), _region(observed, window)
    if seen is None:
        return np.zeros(last.shape, np.float32)
    # now - t falls as t grows, so its range is (now - newest, now - oldest), the same floats
    return _scaled(now - last, obs & np.isfinite(last), now - seen[1], now - seen[0])


def min_distance(observed: np.ndarray, distance: np.ndarray, max_distance: float = 100.0,
                 window: GridWindow | None = None) -> np.ndarray:
    """Closest observation distance / ``max_distance``; farther than that counts as unobserved (0)."""
    _check_like("min_distance", distance, _check_mask(observed))
    if not max_distance > 0:
        raise ValueError(f"max_distance: must be > 0, got {max_distance}")
    distance, observed = _region(distance, window), _region(observed, window)
    seen = observed & (distance <= max_distance)
    return np.where(seen, distance / np.float32(max_distance), np.float32(0)).astype(np.float32, copy=False)


def elevation(observed: np.ndarray, top: np.ndarray, window: GridWindow | None = None,
              span: tuple[float, float] | None = None) -> np.ndarray:
    """Top of the highest occupied voxel scaled over observed columns (lowest 0, highest 1).

    ``span``: the whole grid's (lowest, highest), as for ``time_since_seen``.
    """
    _check_like("elevation", top, _check_mask(observed))
    span = observed_range(top, observed) if span is None else span
    top, obs = _region(top, window), _region(observed, window)
    if span is None:
        return np.zeros(top.shape, np.float32)
    return _scaled(top, obs & np.isfinite(top), *span)


def color(observed: np.ndarray, rgb: np.ndarray) -> np.ndarray:
    """The top voxel's RGB as float32 (h, w, 3) in [0, 1]; black where unobserved. For people only."""
    _check_like("color", rgb, _check_mask(observed))
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"color: expected (h, w, 3) uint8, got {rgb.shape} {rgb.dtype}")
    return np.where(observed[..., None], rgb.astype(np.float32) / 255.0, np.float32(0)).astype(np.float32)
