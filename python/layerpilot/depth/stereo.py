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
        keep = raw > 0
        rejected["no_match"] = keep.size - np.count_nonzero(keep)  # SGBM's uniqueness and speckle (and its left-right) rejections
        h, w = raw.shape
        matched = np.arange(w, dtype=np.float32)[None, :] - raw  # the partner's column of each pixel's match
        if c.lr_check == "mirrored":  # the right view's disparities from matching the mirrored pair
            right = self._match(pair.right[:, ::-1], pair.left[:, ::-1])[:, ::-1]
            keep = _passed(rejected, "left_right", keep,  # rint(matched) >= 0, i.e. matched >= -0.5
                           (matched >= -0.5) & (np.abs(_at_match(right, matched) - raw) <= c.lr_max_diff))
        if c.min_texture > 0:
            keep = _passed(rejected, "texture", keep, _local_std(pair.left, c.block_size) >= c.min_texture)
        if c.max_disparity_step > 0:
            spread = cv2.morphologyEx(np.where(keep, raw, np.float32(0)), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8))
            keep = _passed(rejected, "discontinuity", keep, spread <= c.max_disparity_step)
        keep = _passed(rejected, "edge_margin", keep, (_eroded(pair.left_valid, c.edge_margin) > 0)
                       & (_at_match(_eroded(pair.right_valid, c.edge_margin), matched) > 0))
        with np.errstate(divide="ignore"):
            depth = np.float32(pair.f * pair.baseline) / raw
        keep = _passed(rejected, "depth_range", keep, (depth >= c.min_depth) & (depth <= c.max_depth))
        return Disparity(pair, np.where(keep, raw, np.float32(np.nan)), np.where(keep, depth, np.float32(np.nan)), rejected)

    def sgbm_only(self, pair: RectifiedPair) -> np.ndarray:
        """One bare OpenCV SGBM call on a rectified pair, without its left-right check (the bench's speed reference)."""
        return self._bare.compute(pair.left, pair.right)

    def _match(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """SGBM disparity in pixels; both images are padded on the left so that SGBM's blind
        band (the first ``num_disparities`` columns) falls outside the image."""
        n = self.config.num_disparities
        pad = [cv2.copyMakeBorder(np.ascontiguousarray(im), 0, 0, n, 0, cv2.BORDER_CONSTANT, value=0)
               for im in (left, right)]
        return np.multiply(self._sgbm.compute(*pad)[:, n:], np.float32(1 / 16), dtype=np.float32)  # exact: a power of 2

    def cloud(self, ref: CameraFrame, other: CameraFrame) -> tuple[PointCloud, Disparity]:
        """Points seen from ``ref`` (origin = ref's camera centre, stamp = ref's stamp)."""
        disp = self.disparity(ref, other)
        pair = disp.pair
        h, w = disp.depth.shape
        found = np.flatnonzero(np.isfinite(disp.depth))  # flat indices: np.take gathers faster than a 2D mask
        z = np.take(disp.depth, found)
        f = np.float32(pair.f)
        canon = np.empty((len(z), 3), np.float32)
        canon[:, 0] = np.take(np.tile((np.arange(w, dtype=np.float32) - np.float32(pair.cx)) / f, h), found) * z
        canon[:, 1] = np.take(np.repeat((np.arange(h, dtype=np.float32) - np.float32(pair.cy)) / f, w), found) * z
        canon[:, 2] = z
        colors = np.take(pair.colors.reshape(-1, 3), found, axis=0)
        return camera_points_to_cloud(ref, canon, colors, pair.to_camera), disp


def _sgbm(c: MatchConfig, disp12_max_diff: int) -> cv2.StereoSGBM:
    return cv2.StereoSGBM_create(
        minDisparity=0, numDisparities=c.num_disparities, blockSize=c.block_size,
        P1=8 * c.block_size ** 2, P2=32 * c.block_size ** 2, disp12MaxDiff=disp12_max_diff, preFilterCap=31,
        uniquenessRatio=c.uniqueness_ratio, speckleWindowSize=c.speckle_window,
        speckleRange=c.speckle_range, mode=_MODES[c.mode])


def _passed(rejected: Counter, name: str, keep: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """``keep & ok``, the pixels it removes counted under ``name``."""
    kept = keep & ok
    rejected[name] = int(np.count_nonzero(keep)) - int(np.count_nonzero(kept))
    return kept


def _at_match(image: np.ndarray, matched: np.ndarray) -> np.ndarray:
    """``image`` (the partner's canonical view) at each pixel's match: row unchanged, column
    ``rint(matched)`` clipped to the image (remap's nearest rounds half to even, its replicated border clamps)."""
    rows = np.broadcast_to(np.arange(matched.shape[0], dtype=np.float32)[:, None], matched.shape)
    return cv2.remap(image, matched, np.ascontiguousarray(rows), cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)


def _local_std(image: np.ndarray, block: int) -> np.ndarray:
    im = image.astype(np.float32)
    mean = cv2.blur(im, (block, block))
    var = cv2.blur(im * im, (block, block))
    var -= mean * mean
    return np.sqrt(np.maximum(var, 0.0, out=var), out=var)


def _eroded(mask: np.ndarray, margin: int) -> np.ndarray:
    """uint8 ``mask`` without ``margin`` pixels along its border (nonzero = inside)."""
    mask = mask.view(np.uint8)
    if margin <= 0:
        return mask
    k = np.ones((2 * margin + 1, 2 * margin + 1), np.uint8)
    return cv2.erode(mask, k, borderType=cv2.BORDER_CONSTANT, borderValue=0)
