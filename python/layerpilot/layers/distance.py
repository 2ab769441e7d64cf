"""The fringe's distance transform, kept up to date over the columns that changed since last time.

The fringe needs, for every observed column, the exact Euclidean distance to the nearest
unobserved one (after a closing that fills small holes). A whole-grid transform costs
19 ms at 1024 x 1024, yet between two decision ticks the camera changes only the columns
under its footprint. ``ClosedDistance`` keeps the last closed mask and its transform and,
given a new observed mask, redoes only what the change can reach:

1. the closing, on the box of changed columns grown by the kernel's reach;
2. the distance, on the cells whose value can change. A cell p keeps its distance d(p)
   unless a changed cell lies within d(p) of it (its nearest unobserved column was not
   touched and no new one is nearer), so only cells with d(p) >= dist(p, changed box)
   are recomputed: on a box around them, from a transform of that box plus a margin,
   trusted where no cell beyond the margin could be nearer, the margin growing until
   every cell is trusted (at worst, the whole grid).

The result equals a whole-grid transform of the same mask (to OpenCV's float32 rounding,
which depends on the image size: 1 ulp; tests/test_decide_window.py).
"""

from __future__ import annotations

import threading

import cv2
import numpy as np

from layerpilot.grid import GridGeometry, GridWindow


def closed_mask(observed: np.ndarray, closing: int) -> np.ndarray:
    """uint8 0/1: ``observed`` after a closing with an elliptic ``closing`` kernel (<= 1: none)."""
    mask = np.ascontiguousarray(observed).view(np.uint8)
    if closing <= 1:
        return mask.copy()
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (closing, closing))
    return cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel)


def _transform(mask: np.ndarray) -> np.ndarray:
    return cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def _box(changed: np.ndarray) -> GridWindow | None:
    rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
    if rows.size == 0:
        return None
    return GridWindow(int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)


def _changed(old: np.ndarray, new: np.ndarray) -> GridWindow | None:
    """The box of cells where two bool masks differ, comparing 8 cells at a time where rows allow."""
    if old.shape[1] % 8 or not (old.flags.c_contiguous and new.flags.c_contiguous):
        return _box(old != new)
    coarse = _box(old.view(np.uint64) != new.view(np.uint64))
    if coarse is None:
        return None
    cols = slice(8 * coarse.col0, 8 * coarse.col1)
    fine = _box(old[coarse.row0:coarse.row1, cols] != new[coarse.row0:coarse.row1, cols])
    return GridWindow(fine.row0 + coarse.row0, fine.row1 + coarse.row0,
                      fine.col0 + 8 * coarse.col0, fine.col1 + 8 * coarse.col0)


def _gap(lo: int, hi: int, n: int) -> np.ndarray:
    """Per index 0..n-1: cells to the range [lo, hi) (0 inside), float32: a lower bound of the distance to it."""
    i = np.arange(n, dtype=np.float32)
    return np.maximum(np.maximum(np.float32(lo) - i, i - np.float32(hi - 1)), np.float32(0))


def _beyond(window: GridWindow, trusted: GridWindow, shape: tuple[int, int]) -> np.ndarray:
    """Per cell of ``window``: distance to the nearest cell outside ``trusted`` across an inner edge (inf if none)."""
    h, w = shape
    rows = np.arange(window.row0, window.row1, dtype=np.float32)[:, None]
    cols = np.arange(window.col0, window.col1, dtype=np.float32)[None, :]
    near = np.full(window.shape, np.inf, np.float32)
    for inner, gap in ((trusted.row0 > 0, rows - trusted.row0 + 1), (trusted.row1 < h, trusted.row1 - rows),
                       (trusted.col0 > 0, cols - trusted.col0 + 1), (trusted.col1 < w, trusted.col1 - cols)):
        if inner:
            np.minimum(near, gap, out=near)
    return near


def distance_on(mask: np.ndarray, window: GridWindow, margin: int = 16) -> np.ndarray:
    """The whole-grid distance transform of ``mask``, on ``window`` only, from as little of the grid as exactness allows.

    A cell's distance d from a transform of the window plus ``margin`` is exact when it is
    no larger than the distance to the nearest cell beyond the margin (OpenCV treats the
    image's outside as observed). The true distance is at most d, so a margin grown by the
    largest shortfall makes every cell exact on the second pass.
    """
    geometry = GridGeometry(0.0, 0.0, 1.0, mask.shape[1], mask.shape[0])
    while True:
        around = window.grown(margin, geometry)
        if around == GridWindow.full(geometry):
            return _transform(mask)[window.slices]
        dist = _transform(np.ascontiguousarray(mask[around.slices]))[window.within(around)]
        short = float((dist - _beyond(window, around, mask.shape)).max())
        if short <= 0:
            return dist
        margin += int(np.ceil(min(short, 1e9))) + 1


class ClosedDistance:
    """The closed mask and its distance transform for the last observed mask seen, updated incrementally."""

    def __init__(self, closing: int) -> None:
        self.closing = closing
        self.reach = 2 * (closing // 2) if closing > 1 else 0  # a closing reads this far (dilate, then erode)
        self.observed: np.ndarray | None = None
        self.closed: np.ndarray | None = None
        self.dist: np.ndarray | None = None
        self.zeros = 0  # unobserved cells of the closed mask
        self.row_max: np.ndarray | None = None  # largest distance of each row and column, kept with ``dist``
        self.col_max: np.ndarray | None = None
        self.lock = threading.Lock()  # hold it across ``update`` and reading what it returns

    def update(self, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(closed mask, distance transform) of ``observed``: read-only arrays, valid until the next update."""
        if self.observed is None or self.observed.shape != observed.shape:
            self._whole(observed)
        else:
            changed = _changed(self.observed, observed)
            if changed is not None:
                self._patch(observed, changed)
        return self.closed, self.dist

    def _whole(self, observed: np.ndarray) -> None:
        self.observed = observed.copy()
        self.closed = closed_mask(observed, self.closing)
        self.zeros = int(self.closed.size - np.count_nonzero(self.closed))
        self.dist = _transform(self.closed)
        self.row_max, self.col_max = self.dist.max(axis=1), self.dist.max(axis=0)

    def _patch(self, observed: np.ndarray, changed: GridWindow) -> None:
        h, w = observed.shape
        geometry = GridGeometry(0.0, 0.0, 1.0, w, h)
        self.observed[changed.slices] = observed[changed.slices]
        touched = changed.grown(self.reach, geometry)  # closed cells that may differ
        read = touched.grown(self.reach, geometry)  # what the closing of those reads
        fresh = closed_mask(observed[read.slices], self.closing)[touched.within(read)]
        flipped = _box(fresh != self.closed[touched.slices])
        self.zeros += int(np.count_nonzero(fresh == 0)) - int(np.count_nonzero(self.closed[touched.slices] == 0))
        self.closed[touched.slices] = fresh
        if flipped is None:
            return
        flipped = GridWindow(flipped.row0 + touched.row0, flipped.row1 + touched.row0,
                             flipped.col0 + touched.col0, flipped.col1 + touched.col0)
        # cells whose nearest unobserved column may have moved: d(p) >= distance from p to the flipped box.
        # Their box lies within the rows whose largest d reaches the box's rows, and the same for columns.
        rows = np.flatnonzero(self.row_max >= _gap(flipped.row0, flipped.row1, h) - 1e-3)
        cols = np.flatnonzero(self.col_max >= _gap(flipped.col0, flipped.col1, w) - 1e-3)
        stale = GridWindow(int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)
        self.dist[stale.slices] = distance_on(self.closed, stale)
        self.row_max[stale.row0:stale.row1] = self.dist[stale.row0:stale.row1].max(axis=1)
        self.col_max[stale.col0:stale.col1] = self.dist[:, stale.col0:stale.col1].max(axis=0)
