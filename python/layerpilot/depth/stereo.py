"""Semi-global matching and the filters that keep only trustworthy depths.

OpenCV's StereoSGBM matches the canonical pair (see ``rectify``); its own
uniqueness and speckle filters run inside. Left-right consistency (``lr_check``):
SGBM's own (``disp12MaxDiff``, the right view's disparities from the same cost volume:
the live presets) or the mirrored pair matched a second time (twice the SGBM time;
the photos, where it kept more of the points within 1 m). Around it: an edge
margin around the valid rectified area of both images, and a
depth window ``[min_depth, max_depth]`` (100 m by default). Survivors are
triangulated, ``Z = f * B / d``, and moved into the map frame.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import math

import cv2
import numpy as np

from layerpilot.depth.config import MatchConfig
from layerpilot.depth.backproject import camera_points_to_cloud
from layerpilot.depth.rectify import RectifiedPair, rectify
from layerpilot.geometry import CameraFrame, PointCloud

_MODES = {"sgbm": cv2.STEREO_SGBM_MODE_SGBM, "sgbm_3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY,
          "hh": cv2.STEREO_SGBM_MODE_HH, "hh4": cv2.STEREO_SGBM_MODE_HH4}


@dataclass(frozen=True)
class Disparity:
    """Filtered disparity of a canonical pair; NaN where a filter rejected the pixel."""

    pair: RectifiedPair
    disparity: np.ndarray  # float32 (H, W), pixels at matching scale
    depth: np.ndarray  # float32 (H, W), metres along the canonical optical axis, NaN = none
    rejected: Counter  # pixels removed per filter, in the order applied


class StereoMatcher:
    """Rectify, match and filter one frame pair; ``cloud`` gives map-frame points."""

    def __init__(self, config: MatchConfig = MatchConfig()) -> None:
        self.config = config
        c = config
        self._bare = _sgbm(c, disp12_max_diff=-1)
        self._sgbm = _sgbm(c, disp12_max_diff=math.ceil(c.lr_max_diff)) if c.lr_check == "sgbm" else self._bare

    def disparity(self, ref: CameraFrame, other: CameraFrame) -> Disparity:
        c = self.config
        pair = rectify(ref, other, c.scale)
        raw = self._match(pair.left, pair.right)
        rejected: Counter = Counter()
        h, w = raw.shape
        keep = raw > 0
        rejected["no_match"] = int((~keep).sum())  # SGBM's uniqueness and speckle (and its left-right) rejections
        cols = np.arange(w, dtype=np.float32)[None, :]
        ur = np.rint(cols - raw).astype(np.int32)
        urc = np.clip(ur, 0, w - 1)
        rows = np.arange(h)[:, None]
        if c.lr_check == "mirrored":  # the right view's disparities from matching the mirrored pair
            right = self._match(pair.right[:, ::-1], pair.left[:, ::-1])[:, ::-1]
            lr_ok = keep & (ur >= 0) & (np.abs(right[rows, urc] - raw) <= c.lr_max_diff)
            rejected["left_right"] = int((keep & ~lr_ok).sum())
            keep = lr_ok
        if c.min_texture > 0:
            textured = keep & (_local_std(pair.left, c.block_size) >= c.min_texture)
            rejected["texture"] = int((keep & ~textured).sum())
            keep = textured
        if c.max_disparity_step > 0:
            d0 = np.where(keep, raw, 0).astype(np.float32)
            k3 = np.ones((3, 3), np.uint8)
            smooth = keep & (cv2.dilate(d0, k3) - cv2.erode(d0, k3) <= c.max_disparity_step)
            rejected["discontinuity"] = int((keep & ~smooth).sum())
            keep = smooth
        margin_ok = keep & _eroded(pair.left_valid, c.edge_margin) & _eroded(pair.right_valid, c.edge_margin)[rows, urc]
        rejected["edge_margin"] = int((keep & ~margin_ok).sum())
        keep = margin_ok
        with np.errstate(divide="ignore"):
            depth = np.float32(pair.f * pair.baseline) / raw
        range_ok = keep & (depth >= c.min_depth) & (depth <= c.max_depth)
        rejected["depth_range"] = int((keep & ~range_ok).sum())
        disparity = np.where(range_ok, raw, np.nan).astype(np.float32)
        return Disparity(pair, disparity, np.where(range_ok, depth, np.nan).astype(np.float32), rejected)

    def sgbm_only(self, pair: RectifiedPair) -> np.ndarray:
        """One bare OpenCV SGBM call on a rectified pair, without its left-right check (the bench's speed reference)."""
        return self._bare.compute(pair.left, pair.right)

    def _match(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """SGBM disparity in pixels; both images are padded on the left so that SGBM's blind
        band (the first ``num_disparities`` columns) falls outside the image."""
        n = self.config.num_disparities
        pad = [cv2.copyMakeBorder(np.ascontiguousarray(im), 0, 0, n, 0, cv2.BORDER_CONSTANT, value=0)
               for im in (left, right)]
        return self._sgbm.compute(*pad)[:, n:].astype(np.float32) / 16.0

    def cloud(self, ref: CameraFrame, other: CameraFrame) -> tuple[PointCloud, Disparity]:
        """Points seen from ``ref`` (origin = ref's camera centre, stamp = ref's stamp)."""
        disp = self.disparity(ref, other)
        pair = disp.pair
        found = np.isfinite(disp.depth)  # boolean masks: one pass each, no index arrays
        h, w = found.shape
        z = disp.depth[found]
        canon = np.empty((len(z), 3), np.float32)
        f = np.float32(pair.f)
        canon[:, 0] = np.broadcast_to((np.arange(w, dtype=np.float32) - np.float32(pair.cx)) / f, (h, w))[found] * z
        canon[:, 1] = np.broadcast_to(((np.arange(h, dtype=np.float32) - np.float32(pair.cy)) / f)[:, None], (h, w))[found] * z
        canon[:, 2] = z
        colors = ref.image.reshape(-1, 3)[pair.source_index[found]]
        return camera_points_to_cloud(ref, canon, colors, pair.to_camera), disp


def _sgbm(c: MatchConfig, disp12_max_diff: int) -> cv2.StereoSGBM:
    return cv2.StereoSGBM_create(
        minDisparity=0, numDisparities=c.num_disparities, blockSize=c.block_size,
        P1=8 * c.block_size ** 2, P2=32 * c.block_size ** 2, disp12MaxDiff=disp12_max_diff, preFilterCap=31,
        uniquenessRatio=c.uniqueness_ratio, speckleWindowSize=c.speckle_window,
        speckleRange=c.speckle_range, mode=_MODES[c.mode])


def _local_std(image: np.ndarray, block: int) -> np.ndarray:
    im = image.astype(np.float32)
    mean = cv2.blur(im, (block, block))
    return np.sqrt(np.maximum(cv2.blur(im * im, (block, block)) - mean * mean, 0.0))


def _eroded(mask: np.ndarray, margin: int) -> np.ndarray:
    if margin <= 0:
        return mask
    k = np.ones((2 * margin + 1, 2 * margin + 1), np.uint8)
    return cv2.erode(mask.astype(np.uint8), k, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
