"""View gain: how much unobserved or stale area of the area of interest a camera would see from each cell.

The frontier layer says where the edge of the map is; a camera at 50 m pitched 60 deg down
sees tens of metres *ahead* of the drone, so the best place to stand is not the edge but the
spot whose footprint covers the most unseen ground. For a candidate cell c this layer is

    gain(c) = sum over target cells t in F(c) visible from c of w(t)  /  |F|

where F(c) is the camera's ground footprint when the drone stands over c (from the mission
altitude, pitch, fields of view and the map's range limit), w(t) is 1 for an unobserved cell of
the area of interest, ``min(1, age / stale_s)`` for an observed one and 0 outside the area, and
|F| the footprint's size: the value is the fraction of the footprint that is worth seeing, in
[0, 1], comparable from one tick to the next.

The camera's heading at the candidate decides where the footprint lies (``heading_yaw``, the
one rule the pilot's commands also follow): a fixed heading (one footprint for every cell: one
correlation), facing the area's centre, facing the direction of travel from the drone, or
looking sideways to it; all but the first quantise the heading into ``SECTORS`` and correlate
once per sector present.

Occlusion by the elevation layer: a column taller than the target between it and the camera
hides it from far enough away. Along the direction towards the camera the target's largest
visible distance is ``min_s (A - z_t) s / (z(s) - z_t)`` over occluders at distance s with
z(s) > z_t (A: camera height); it is sampled at ``OCCLUDER_STEPS``. The footprint is split
into distance bands and a target counts in a band only if it stays visible to the band's far
edge. Work is done on a grid of about 2 m cells (area-averaged), then scaled back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import cv2
import numpy as np

SECTORS = 8  # heading bins when the heading differs per candidate
BANDS = 3  # distance bands of the footprint for occlusion
OCCLUDER_STEPS = (1.0, 2.0, 3.0, 4.0, 6.0, 9.0, 13.0, 19.0, 27.0, 40.0)  # metres from the target
WORK_CELL = 4.0  # metres: the working grid's cell size (never finer than the map's)


HEADINGS = ("target", "side", "fixed", "center")


def heading_yaw(rule: str, position: tuple[float, ...] | None, x, y, yaw: float = 0.0,
                center: tuple[float, float] = (0.0, 0.0)):
    """The camera heading (ENU rad) on the way from ``position`` to (x, y) under a heading rule.

    ``target``: along the track; ``side``: 90 deg to the track, on the side of ``center``
    (sideways motion, the best for two-view stereo); ``fixed``: ``yaw``; ``center``: towards
    ``center`` from (x, y). Works on numbers and on arrays of candidates alike.
    """
    if rule == "fixed":
        return math.atan2(math.sin(yaw), math.cos(yaw))
    if rule == "center":
        return np.arctan2(center[1] - y, center[0] - x)
    if rule not in ("target", "side"):
        raise ValueError(f"heading: expected one of {', '.join(HEADINGS)}, got {rule!r}")
    if position is None:
        raise ValueError(f"heading {rule!r}: the camera's heading depends on the drone's position; none given")
    tx, ty = np.subtract(x, position[0]), np.subtract(y, position[1])
    track = np.arctan2(ty, tx)
    if rule == "target":
        return track
    left = tx * (center[1] - y) - ty * (center[0] - x) >= 0  # the centre lies left of the track
    side = track + np.where(left, np.pi / 2, -np.pi / 2)
    return np.arctan2(np.sin(side), np.cos(side))


@dataclass(frozen=True)
class CameraView:
    """Where the camera would look from a candidate: height over the ground, mount, range, heading rule."""

    height: float  # m above the ground the targets lie on
    pitch_deg: float  # below the horizon
    hfov_deg: float
    vfov_deg: float
    max_range: float  # m: the map keeps nothing farther from the camera
    heading: str = "target"  # a rule of heading_yaw
    yaw: float = 0.0  # ENU rad, for heading "fixed"
    center: tuple[float, float] = (0.0, 0.0)  # the area's centre, for "center" and "side"

    def __post_init__(self) -> None:
        for name in ("height", "pitch_deg", "hfov_deg", "vfov_deg", "max_range"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"view.{name}: must be finite, got {value}")
        if not self.height > 0 or not self.max_range > self.height:
            raise ValueError(f"view: need 0 < height < max_range, got height {self.height}, max_range {self.max_range}")
        if not 0 < self.pitch_deg <= 90:
            raise ValueError(f"view.pitch_deg: the camera must look down (0, 90], got {self.pitch_deg}")
        if self.heading not in HEADINGS:
            raise ValueError(f"view.heading: expected one of {', '.join(HEADINGS)}, got {self.heading!r}")
        if not (0 < self.hfov_deg < 180 and 0 < self.vfov_deg < 180):
            raise ValueError(f"view: fields of view must be in (0, 180), got {self.hfov_deg}, {self.vfov_deg}")

    @property
    def reach(self) -> float:
        """Farthest ground distance the map keeps (slant range limit over flat ground)."""
        return math.sqrt(self.max_range**2 - self.height**2)


def footprint(view: CameraView, yaw: float, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Ground cells (offsets from the camera, rows along +y) the camera sees over flat ground.

    Returns (mask float32 (2k+1, 2k+1), horizontal distance of each offset in metres).
    """
    k = int(math.ceil(view.reach / cell))
    off = (np.arange(-k, k + 1) * cell).astype(np.float64)
    dx, dy = np.meshgrid(off, off)
    th = math.radians(view.pitch_deg)
    forward = (math.cos(yaw) * math.cos(th), math.sin(yaw) * math.cos(th), -math.sin(th))
    right = (math.sin(yaw), -math.cos(yaw), 0.0)
    down = np.cross(forward, right)
    vz = -view.height
    zc = dx * forward[0] + dy * forward[1] + vz * forward[2]
    xc = dx * right[0] + dy * right[1]
    yc = dx * down[0] + dy * down[1] + vz * down[2]
    ground = np.hypot(dx, dy)
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = ((zc > 0) & (np.abs(xc) <= zc * math.tan(math.radians(view.hfov_deg) / 2))
                  & (np.abs(yc) <= zc * math.tan(math.radians(view.vfov_deg) / 2))
                  & (ground**2 + view.height**2 <= view.max_range**2))
    return inside.astype(np.float32), ground


def target_weights(observed: np.ndarray, last_seen: np.ndarray, aoi: np.ndarray, now: float,
                   stale_s: float) -> np.ndarray:
    """w(t): 1 unobserved, min(1, age / stale_s) observed, 0 outside the area of interest."""
    if not (observed.shape == last_seen.shape == aoi.shape):
        raise ValueError(f"observed, last_seen, aoi: shapes differ: {observed.shape}, {last_seen.shape}, {aoi.shape}")
    if not stale_s > 0:
        raise ValueError(f"stale_s: must be > 0, got {stale_s}")
    age = np.nan_to_num((now - last_seen) / stale_s, nan=1.0, posinf=1.0, neginf=0.0)
    w = np.where(observed, np.clip(age, 0.0, 1.0), 1.0).astype(np.float32)
    w[~aoi] = 0.0
    return w


def visible_distance(top: np.ndarray, height: float, yaw: float, cell: float) -> np.ndarray:
    """Largest horizontal distance (m) from which a camera ``height`` up, looking along ``yaw``, sees each cell.

    ``top``: column tops (NaN unknown: neither occludes nor is occluded beyond the ground, taken
    as the lowest known top). The camera stands behind the target, at bearing yaw + pi.
    """
    known = np.isfinite(top)
    ground = float(np.min(top[known])) if known.any() else 0.0
    z = np.where(known, top, ground).astype(np.float32)
    occluder = np.where(known, top, -np.inf).astype(np.float32)
    best = np.full(z.shape, np.inf, np.float32)
    ux, uy = -math.cos(yaw), -math.sin(yaw)  # from the target towards the camera
    lift = np.maximum(np.float32(height) - z, np.float32(1e-3))
    h, w = z.shape
    for s in OCCLUDER_STEPS:
        dc, dr = int(round(ux * s / cell)), int(round(uy * s / cell))
        if dc == 0 and dr == 0:
            continue
        shifted = np.full(z.shape, -np.inf, np.float32)  # occluder at target + (dr, dc)
        shifted[max(0, -dr):h - max(0, dr), max(0, -dc):w - max(0, dc)] = \
            occluder[max(0, dr):h - max(0, -dr), max(0, dc):w - max(0, -dc)]
        rise = shifted - z
        dist = math.hypot(dr, dc) * cell
        with np.errstate(divide="ignore", invalid="ignore"):
            limit = np.where(rise > 0, lift * np.float32(dist) / rise, np.inf)
        np.minimum(best, limit, out=best)
    return best


CandidateYaw = float | np.ndarray | Callable[[np.ndarray, np.ndarray], np.ndarray]  # per candidate (see view_gain)


def view_gain(observed: np.ndarray, last_seen: np.ndarray, top: np.ndarray, aoi: np.ndarray, now: float,
              resolution: float, view: CameraView, yaw: CandidateYaw, stale_s: float = 300.0) -> np.ndarray:
    """The layer: fraction of the candidate's footprint worth seeing, float32 in [0, 1].

    ``yaw``: the camera's heading at each candidate: one number, a (h, w) array, or a function of
    (rows, cols) index arrays giving it at those cells only (the working grid needs one cell in
    ``WORK_CELL / resolution`` squared, so the heading is computed where it is used).
    """
    if observed.ndim != 2 or observed.dtype != np.bool_:
        raise ValueError(f"observed: expected a 2D bool array, got {observed.shape} {observed.dtype}")
    if not resolution > 0:
        raise ValueError(f"resolution: must be > 0, got {resolution}")
    if top.shape != observed.shape:
        raise ValueError(f"top: expected shape {observed.shape}, got {top.shape}")
    factor = max(1, int(round(WORK_CELL / resolution)))
    cell = resolution * factor
    h, w = observed.shape
    small = (max(1, w // factor), max(1, h // factor))
    weights = cv2.resize(target_weights(observed, last_seen, aoi, now, stale_s), small, interpolation=cv2.INTER_AREA)
    tops = cv2.resize(np.where(np.isfinite(top), top, np.nan).astype(np.float32), small,
                      interpolation=cv2.INTER_NEAREST)
    if callable(yaw):
        rows, cols = nearest_cells((h, w), small)
        yaw = np.asarray(yaw(rows[:, None], cols[None, :]), np.float32)
    elif np.ndim(yaw) != 0:
        yaw = cv2.resize(np.asarray(yaw, np.float32), small, interpolation=cv2.INTER_NEAREST)
    if np.ndim(yaw) == 0:
        gain = _gain_one(weights, tops, view, float(yaw), cell)
    else:
        sector = np.mod(np.round(yaw / (2 * math.pi / SECTORS)), SECTORS).astype(np.int32)
        gain = np.zeros(weights.shape, np.float32)
        for k in np.unique(sector):
            one = _gain_one(weights, tops, view, 2 * math.pi * k / SECTORS, cell)
            gain[sector == k] = one[sector == k]
    out = cv2.resize(gain, (w, h), interpolation=cv2.INTER_LINEAR)
    return np.clip(out, 0.0, 1.0, out=out)


@lru_cache(maxsize=16)
def nearest_cells(shape: tuple[int, int], small: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The rows and columns of a ``shape`` grid that OpenCV's nearest-neighbour resize to ``small``
    (width, height) reads: the cells it would copy, found by resizing their indices."""
    h, w = shape
    cols = cv2.resize(np.arange(w, dtype=np.int32)[None, :], (small[0], 1), interpolation=cv2.INTER_NEAREST)[0]
    rows = cv2.resize(np.arange(h, dtype=np.int32)[:, None], (1, small[1]), interpolation=cv2.INTER_NEAREST)[:, 0]
    for a in (rows, cols):
        a.setflags(write=False)
    return rows, cols


def _gain_one(weights: np.ndarray, tops: np.ndarray, view: CameraView, yaw: float, cell: float) -> np.ndarray:
    total, bands = _bands(view, yaw, cell)
    if total == 0:
        return np.zeros(weights.shape, np.float32)
    reach = visible_distance(tops, view.height, yaw, cell)
    gain = np.zeros(weights.shape, np.float32)
    for far, band in bands:
        seen = np.where(reach >= far, weights, np.float32(0))
        gain += cv2.filter2D(seen, cv2.CV_32F, band, borderType=cv2.BORDER_CONSTANT)
    gain *= np.float32(1.0 / total)
    return gain


@lru_cache(maxsize=64)
def _bands(view: CameraView, yaw: float, cell: float) -> tuple[float, tuple[tuple[float, np.ndarray], ...]]:
    """The footprint's size and its distance bands (far edge, kernel), the empty ones left out: the
    same few headings and views come back every tick."""
    mask, ground = footprint(view, yaw, cell)
    edges = np.linspace(0.0, view.reach, BANDS + 1)
    bands = []
    for near, far in zip(edges[:-1], edges[1:]):
        band = mask * ((ground >= near) & (ground < far if far < edges[-1] else ground <= far))
        if band.any():
            band.setflags(write=False)
            bands.append((float(far), band))
    return float(mask.sum()), tuple(bands)


def layer(columns, voxel_map, context) -> np.ndarray:
    """The registered ``view_gain`` layer; the context must carry ``view`` and ``aoi``."""
    if context.view is None or context.aoi is None:
        raise ValueError("view_gain: the layer context needs the camera view and the area of interest "
                         "(the mission's pilot provides both)")
    g = columns.geometry
    xs, ys = g.cell_centers()
    v = context.view

    def yaw(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return heading_yaw(v.heading, context.position, xs[rows, cols], ys[rows, cols], v.yaw, v.center)

    return view_gain(columns.observed, columns.last_seen, columns.elevation, context.aoi, context.now,
                     g.resolution, context.view, yaw, context.options.view_stale_s)
