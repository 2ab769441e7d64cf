"""Grid layers on the bus (proto ``LayerSet``): a grid geometry plus named 2D layers in a compact encoding.

``GridLayersMessage`` is the wire form (what the map server publishes: its column layers, or any
named arrays); the decision maker's feature layers are ``layerpilot.layers.FeatureLayers``.

Floats travel as float16 or as uint8/uint16 with scale and offset (the top three codes
mean -inf, +inf and NaN), booleans as packed bits, colors raw; everything LZ4'd (a
512 x 512 set in about a millisecond: zlib took ten). If a set would exceed
``max_bytes`` (1 MB by default) it is zlib'd instead, then quantized layers fall back to
uint8, and a set that is still too big is refused with its size, so a query cannot flood
the bus.

A large survey's set carries only the drone's neighbourhood in full (``window``): its
``observed`` covers the whole grid (the pilot's coverage and fringe read all of it) and
the ranges the layers are scaled by travel as two numbers each (``ColumnLayers``), so a
1 km area is a few hundred kilobytes at most instead of megabytes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from layerpilot.bus import arrays, limits
from layerpilot.bus.keys import check_vehicle
from layerpilot.bus.messages import _finite, _vehicle, parse
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage
from layerpilot.grid import GridGeometry, GridWindow
from layerpilot.map.columns import RANGED, ColumnLayers, observed_range

MAX_BYTES = 1_000_000
ENCODINGS = {"raw": pb.Layer.RAW, "float16": pb.Layer.FLOAT16, "uint8": pb.Layer.UINT8,
             "uint16": pb.Layer.UINT16, "bits": pb.Layer.BITS}
_QUANT = {pb.Layer.UINT8: np.uint8, pb.Layer.UINT16: np.uint16}
# how the map server's column layers travel unless asked otherwise
COLUMN_ENCODINGS = {"observed": "bits", "elevation": "float16", "color": "raw",
                    "last_seen": "uint16", "min_distance": "float16"}
WHOLE = ("observed",)  # layers that cover the whole grid even in a windowed set
# what a windowed set's arrays read as outside the window (ColumnLayers' unobserved values)
_UNOBSERVED = {"elevation": np.nan, "color": 0, "last_seen": np.nan, "min_distance": np.inf}


@dataclass(frozen=True)
class GridLayersMessage:
    """``layerpilot/<vehicle>/layers`` and the ``map/layers`` reply: named arrays on one grid."""

    stamp: float
    vehicle: str
    geometry: GridGeometry
    layers: dict[str, np.ndarray]  # each (height, width) or (height, width, channels); with window: its shape
    window: GridWindow | None = None  # set: every layer but those in WHOLE holds only these cells
    ranges: dict[str, tuple[float, float]] | None = None  # with window: whole-grid (min, max) per RANGED layer


def column_arrays(cl: ColumnLayers, names: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The named arrays of a ColumnLayers (all of them by default); ValueError names an unknown one."""
    names = tuple(COLUMN_ENCODINGS) if names is None else names
    unknown = [n for n in names if n not in COLUMN_ENCODINGS]
    if unknown:
        raise ValueError(f"layers: unknown {', '.join(unknown)}; known: {', '.join(COLUMN_ENCODINGS)}")
    return {n: getattr(cl, n) for n in names}


def encode_columns(cl: ColumnLayers, stamp: float, vehicle: str, names: tuple[str, ...] | None = None,
                   window: GridWindow | None = None) -> bytes:
    """A map's column layers as the map server publishes them (the one encoder of the live node and the
    lock-step evaluator, so both drivers' pilots read the same bytes).

    ``window``: only those cells in full (the drone's neighbourhood), plus ``observed`` and the
    value ranges of the whole grid: what a pilot's tick there reads.
    """
    arrays_ = column_arrays(cl, names)
    if window is None:
        return encode_layer_set(GridLayersMessage(stamp, vehicle, cl.geometry, arrays_))
    ranges = {n: r for n in RANGED if n in arrays_ and (r := observed_range(arrays_[n], cl.observed)) is not None}
    arrays_ = {n: a if n in WHOLE else a[window.slices] for n, a in arrays_.items()}
    return encode_layer_set(GridLayersMessage(stamp, vehicle, cl.geometry, arrays_, window, ranges))


def _quantize(m: pb.Layer, arr: np.ndarray, enc: int, codec: str, span: tuple[float, float] | None) -> None:
    qt = _QUANT[enc]
    top = int(np.iinfo(qt).max)
    levels = top - 3  # codes 0..levels are values; top-2 = -inf, top-1 = +inf, top = NaN
    a = np.asarray(arr, np.float64)
    finite = np.isfinite(a)
    lo, hi = _finite_range(a, finite) if span is None else span  # a window: the whole grid's, as its set would
    scale = (hi - lo) / levels if hi > lo else 1.0
    t = np.subtract(a, lo)
    t /= scale
    np.rint(t, out=t)
    with np.errstate(invalid="ignore"):  # NaN and inf cells are overwritten below
        q = t.astype(qt)
    if not (lo == -np.inf or finite.all()):
        q[~finite] = top
        q[a == -np.inf] = top - 2
        q[a == np.inf] = top - 1
    m.scale, m.offset = scale, lo
    arrays.to_proto(q, m.data, compress=codec)


def _finite_range(a: np.ndarray, finite: np.ndarray) -> tuple[float, float]:
    """(min, max) of the finite values (0, 0 if none): NaN-ignoring reductions, masked only if there are infinities."""
    lo, hi = float(np.fmin.reduce(a, axis=None, initial=np.inf)), float(np.fmax.reduce(a, axis=None, initial=-np.inf))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        vals = a[finite]
        lo, hi = (float(vals.min()), float(vals.max())) if vals.size else (0.0, 0.0)
    return lo, hi


def encode_layer(m: pb.Layer, name: str, arr: np.ndarray, encoding: str, codec: str = "lz4",
                 span: tuple[float, float] | None = None) -> None:
    """``span``: quantize over this (min, max) instead of the array's own (it must contain the values)."""
    arr = np.asarray(arr)
    if encoding not in ENCODINGS:
        raise ValueError(f"encoding: unknown {encoding!r} for layer {name}; known: {', '.join(ENCODINGS)}")
    enc = ENCODINGS[encoding]
    m.name, m.encoding, m.dtype = name, enc, arr.dtype.name
    if enc == pb.Layer.BITS:
        if arr.dtype != np.bool_:
            raise ValueError(f"layers[{name}]: bits encoding needs a bool array, got {arr.dtype}")
        arrays.to_proto(np.packbits(arr.ravel()), m.data, compress=codec)
        m.data.shape[:] = arr.shape  # the logical shape; data holds ceil(size / 8) bytes
    elif enc == pb.Layer.RAW:
        arrays.to_proto(arr, m.data, compress=codec)
    elif arr.dtype.kind != "f":
        raise ValueError(f"layers[{name}]: {encoding} encoding needs a float array, got {arr.dtype}")
    elif enc == pb.Layer.FLOAT16:
        arrays.to_proto(arr.astype(np.float16), m.data, compress=codec)
    else:
        _quantize(m, arr, enc, codec, span)


def encode_layer_set(ls: GridLayersMessage, encodings: dict[str, str] | None = None, *,
                     max_bytes: int = MAX_BYTES) -> bytes:
    """Serialize ``ls``; ``encodings`` overrides the per-layer default (COLUMN_ENCODINGS, else raw)."""
    g, win, ranges = ls.geometry, ls.window, ls.ranges or {}
    if win is not None and not GridWindow.full(g).contains(win):
        raise ValueError(f"window: {win} does not lie within the grid {g}")
    chosen = {n: (encodings or {}).get(n, COLUMN_ENCODINGS.get(n, "raw")) for n in ls.layers}
    for chosen, codec in ((chosen, "lz4"), (chosen, "zlib"), (_coarser(chosen), "zlib")):
        m = pb.LayerSet(stamp=float(ls.stamp), vehicle=check_vehicle(ls.vehicle))
        m.grid.CopyFrom(pb.GridGeometry(origin_x=g.origin_x, origin_y=g.origin_y, resolution=g.resolution,
                                        width=g.width, height=g.height))
        if win is not None:
            m.window.CopyFrom(pb.CellWindow(row0=win.row0, row1=win.row1, col0=win.col0, col1=win.col1))
        for name, arr in ls.layers.items():
            shape = g.shape if win is None or name in WHOLE else win.shape
            if np.shape(arr)[:2] != shape:
                raise ValueError(f"layers[{name}]: shape {np.shape(arr)} does not match the grid {shape}")
            encode_layer(m.layers.add(), name, arr, chosen[name], codec, ranges.get(name))
            if name in ranges:  # as the pilot of a whole-grid set would see it: through the same encoding
                lo, hi = _as_sent(name, ranges[name], chosen[name])
                m.ranges.add(layer=name, min=lo, max=hi)
        data = m.SerializeToString()
        if len(data) <= max_bytes:
            return data
    raise ValueError(f"layer set of {g.width}x{g.height} with {', '.join(ls.layers)} is {len(data)} bytes, "
                     f"more than max_bytes={max_bytes}; ask for a smaller window or fewer layers")


def _as_sent(name: str, span: tuple[float, float], encoding: str) -> tuple[float, float]:
    """A range's two ends encoded and decoded as the layer's values are."""
    m = pb.Layer()
    encode_layer(m, name, np.array([span], np.float64), encoding, "lz4", span)
    lo, hi = decode_layer(m, (1, 2))[0]
    return float(lo), float(hi)


def _coarser(chosen: dict[str, str]) -> dict[str, str]:
    return {n: "uint8" if e in ("float16", "uint16") else e for n, e in chosen.items()}


def decode_layer(m: pb.Layer, shape: tuple[int, int]) -> np.ndarray:
    where = f"layers[{m.name}]"
    if m.encoding == pb.Layer.BITS:
        dims = tuple(m.data.shape)
        if dims[:2] != shape:
            raise BadMessage("bad shape", f"{where}: shape {dims} does not match the grid {shape}")
        count = int(np.prod(dims, dtype=np.int64))
        if count > limits.MAX_LAYER_CELLS * 4:
            raise BadMessage("too large", f"{where}: {count} cells is more than the limit")
        packed_msg = pb.Array()
        packed_msg.CopyFrom(m.data)
        packed_msg.shape[:] = [(count + 7) // 8]
        packed = arrays.from_proto(packed_msg, where, dtype="uint8")
        return np.unpackbits(packed, count=count).view(bool).reshape(dims)
    most = shape[0] * shape[1] * 4  # a grid's cells, up to 4 channels (color has 3)
    if m.encoding == pb.Layer.RAW:
        arr = arrays.from_proto(m.data, where, max_items=most)
    elif m.encoding == pb.Layer.FLOAT16:
        arr = arrays.from_proto(m.data, where, dtype="float16", max_items=most)
        arr = arr.astype(m.dtype if m.dtype in ("float32", "float64") else np.float32)
    elif m.encoding in _QUANT:
        qt = _QUANT[m.encoding]
        q = arrays.from_proto(m.data, where, dtype=np.dtype(qt).name, max_items=most)
        if not (math.isfinite(m.scale) and math.isfinite(m.offset)):
            raise BadMessage("not finite", f"{where}: scale/offset")
        top = int(np.iinfo(qt).max)
        out_dtype = m.dtype if m.dtype in ("float32", "float64") else "float32"
        arr = q.astype(np.float64)
        arr *= m.scale
        arr += m.offset
        arr = arr.astype(out_dtype, copy=False)
        if q.max(initial=0) >= top - 2:  # NaN and infinities travel as the top three codes
            for code, value in ((top - 2, -np.inf), (top - 1, np.inf), (top, np.nan)):
                arr[q == code] = value
    else:
        raise BadMessage("bad encoding", f"{where}: unknown encoding {m.encoding}")
    if arr.shape[:2] != shape or arr.ndim not in (2, 3):
        raise BadMessage("bad shape", f"{where}: shape {arr.shape} does not match the grid {shape}")
    return arr


def decode_layer_set(payload: bytes, *, max_cells: int = limits.MAX_LAYER_CELLS) -> GridLayersMessage:
    """``max_cells``: the reader's own cap on the grid (at most the bus's), checked before any layer is decoded."""
    m = parse(pb.LayerSet, payload)
    g = m.grid
    cap = min(max_cells, limits.MAX_LAYER_CELLS)
    if g.width * g.height > cap:
        raise BadMessage("too large", f"grid: {g.width}x{g.height} cells is more than {cap}")
    if len(m.layers) > limits.MAX_LAYERS:
        raise BadMessage("too large", f"layers: {len(m.layers)} is more than {limits.MAX_LAYERS}")
    if not limits.MIN_RESOLUTION <= g.resolution <= limits.MAX_RESOLUTION:
        raise BadMessage("bad grid", f"grid.resolution: {g.resolution} m is outside "
                                     f"[{limits.MIN_RESOLUTION}, {limits.MAX_RESOLUTION}]")
    for name in ("origin_x", "origin_y"):
        if not abs(getattr(g, name)) <= limits.MAX_COORDINATE:
            raise BadMessage("bad grid", f"grid.{name}: {getattr(g, name)} is not within ±{limits.MAX_COORDINATE:g} m")
    try:
        geometry = GridGeometry(_finite(g.origin_x, "grid.origin_x"), _finite(g.origin_y, "grid.origin_y"),
                                _finite(g.resolution, "grid.resolution"), g.width, g.height)
    except ValueError as exc:
        if isinstance(exc, BadMessage):
            raise
        raise BadMessage("bad grid", str(exc)) from None
    window = None
    if m.HasField("window"):
        w = m.window
        try:
            window = GridWindow(w.row0, w.row1, w.col0, w.col1)
        except ValueError as exc:
            raise BadMessage("bad window", str(exc)) from None
        if not GridWindow.full(geometry).contains(window):
            raise BadMessage("bad window", f"window: {window} does not lie within the grid {geometry}")
    layers: dict[str, np.ndarray] = {}
    for lm in m.layers:
        if not lm.name or lm.name in layers:
            raise BadMessage("bad layer name", f"empty or repeated layer name {lm.name!r}")
        layers[lm.name] = decode_layer(lm, geometry.shape if window is None or lm.name in WHOLE else window.shape)
    ranges = {}
    for r in m.ranges:
        if not (math.isfinite(r.min) and math.isfinite(r.max) and r.min <= r.max):
            raise BadMessage("bad range", f"ranges[{r.layer}]: ({r.min}, {r.max}) is not a finite min <= max")
        ranges[r.layer] = (r.min, r.max)
    return GridLayersMessage(_finite(m.stamp, "stamp"), _vehicle(m), geometry, layers, window, ranges)


def to_column_layers(ls: GridLayersMessage) -> ColumnLayers:
    """Rebuild ColumnLayers from a set holding all five column arrays (as the map server publishes)."""
    missing = [n for n in COLUMN_ENCODINGS if n not in ls.layers]
    if missing:
        raise BadMessage("missing layer", ", ".join(missing))
    kinds = {"observed": np.bool_, "elevation": np.float32, "color": np.uint8,
             "last_seen": np.float64, "min_distance": np.float32}
    arrays_ = {n: np.asarray(ls.layers[n]).astype(t, copy=False) for n, t in kinds.items()}
    win = ls.window
    try:
        if win is not None:  # whole-grid arrays, unobserved outside the window
            for n, fill in _UNOBSERVED.items():
                whole = np.full(ls.geometry.shape + arrays_[n].shape[2:], fill, kinds[n])
                whole[win.slices] = arrays_[n]
                arrays_[n] = whole
        return ColumnLayers(ls.geometry, **arrays_, window=win, ranges=dict(ls.ranges or {}))
    except ValueError as exc:
        raise BadMessage("bad layer", str(exc)) from None
