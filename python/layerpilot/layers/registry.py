"""The layer registry: every layer, built-in or user-made, is one named function.

A layer function takes ``(columns, voxel_map, context)`` and returns a float32 array of
the columns' grid shape with values in [0, 1]. ``voxel_map`` is the ``VoxelMap`` the
columns came from, or None when only columns are at hand. Register with
``register_layer("name", fn)`` (or as a decorator); a behavior file then weights it by name
and lists the module that registers it under ``plugins``. See docs/layers.md.

A decision needs the layers only near the drone (a ``GridWindow``). A layer registered
with ``windowed=True`` takes a ``window`` keyword and computes just those cells (the same
values as the whole grid's); any other layer is computed whole and cut to the window.

A layer registered with ``needs`` (names of ``LayerContext`` fields, e.g. the camera view)
is part of the default set only when the context carries them; named explicitly without
them, its function says what is missing.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from layerpilot.layers import features, view_gain
from layerpilot.layers.view_gain import CameraView
from layerpilot.layers.feature_layers import FeatureLayers
from layerpilot.grid import GridWindow
from layerpilot.map.columns import ColumnLayers


@dataclass(frozen=True)
class LayerOptions:
    """Tuning of the built-in layers (the ``[layers]`` table of a behavior file)."""

    fringe_closing: int = 3  # cells; closing kernel that fills small unobserved holes (<= 1: none)
    max_distance: float = 100.0  # metres; observations from farther count as unobserved
    view_stale_s: float = 300.0  # seconds; view_gain counts a cell seen this long ago as fully worth seeing again

    def __post_init__(self) -> None:
        if not 0 <= self.fringe_closing <= 51:
            raise ValueError(f"fringe_closing = {self.fringe_closing} is out of range [0, 51]")
        if not self.max_distance > 0:
            raise ValueError(f"max_distance = {self.max_distance} must be > 0")
        if not self.view_stale_s > 0:
            raise ValueError(f"view_stale_s = {self.view_stale_s} must be > 0")


@dataclass(frozen=True)
class LayerContext:
    """What a layer may know besides the map: the mission clock and where things are."""

    now: float
    home: tuple[float, float] = (0.0, 0.0)  # launch / operator point, map frame
    position: tuple[float, float, float] | None = None  # the drone, if known
    options: LayerOptions = LayerOptions()
    view: CameraView | None = None  # the camera at a candidate (view_gain needs it)
    aoi: np.ndarray | None = None  # bool mask of the area of interest on the columns' grid (view_gain needs it)


LayerFunction = Callable[[ColumnLayers, Any, LayerContext], np.ndarray]
_REGISTRY: dict[str, LayerFunction] = {}
_WINDOWED: set[str] = set()  # layers whose function takes a ``window`` keyword
_NEEDS: dict[str, tuple[str, ...]] = {}  # LayerContext fields a layer cannot do without
RESERVED = frozenset({"color", "observed", "elevation_m"})


def register_layer(name: str, fn: LayerFunction | None = None, *, replace: bool = False,
                   windowed: bool = False, needs: Iterable[str] = ()) -> Any:
    """Add a layer under ``name``; usable as ``register_layer(name, fn)`` or ``@register_layer(name)``.

    ``windowed``: ``fn`` also takes ``window=`` (a ``GridWindow`` or None) and then returns
    only those cells. ``needs``: the ``LayerContext`` fields it cannot be computed without.
    """
    if not name.isidentifier() or name in RESERVED:
        raise ValueError(f"name: {name!r} must be a Python-identifier-like word and not one of {sorted(RESERVED)}")
    needs = tuple(needs)
    fields = set(LayerContext.__dataclass_fields__)
    if unknown := [n for n in needs if n not in fields]:
        raise ValueError(f"needs: {unknown} are not LayerContext fields ({sorted(fields)})")

    def add(f: LayerFunction) -> LayerFunction:
        if name in _REGISTRY and _REGISTRY[name] is not f and not replace:
            raise ValueError(f"name: a layer {name!r} is already registered (pass replace=True to override)")
        _REGISTRY[name] = f
        _WINDOWED.discard(name)
        if windowed:
            _WINDOWED.add(name)
        _NEEDS[name] = needs
        return f

    return add if fn is None else add(fn)


def unregister_layer(name: str) -> None:
    _REGISTRY.pop(name, None)
    _WINDOWED.discard(name)
    _NEEDS.pop(name, None)


def layer_names(context: LayerContext | None = None) -> list[str]:
    """Every registered layer; given a ``context``, only those it carries everything for."""
    if context is None:
        return list(_REGISTRY)
    return [n for n in _REGISTRY if all(getattr(context, field) is not None for field in _NEEDS[n])]


def load_plugins(plugins: Iterable[str], base: Path | None = None) -> None:
    """Import modules that register layers: dotted module names, or .py paths (relative to ``base``)."""
    for plugin in plugins:
        if plugin.endswith(".py"):
            path = Path(plugin)
            if not path.is_absolute() and base is not None:
                path = base / path
            if not path.is_file():
                raise ValueError(f"plugins: no such file {path}")
            path = path.resolve()  # one module per file, however the behavior spells its path
            name = f"layerpilot_plugin_{path.stem}"
            if sys.modules.get(name) is not None and getattr(sys.modules[name], "__file__", None) == str(path):
                continue
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
        else:
            try:
                importlib.import_module(plugin)
            except ImportError as exc:
                raise ValueError(f"plugins: cannot import {plugin!r}: {exc}") from None


def compute_layers(
    columns: ColumnLayers,
    context: LayerContext,
    names: Iterable[str] | None = None,
    voxel_map: Any = None,
    window: GridWindow | None = None,
) -> FeatureLayers:
    """Compute the named layers (default: every one the context allows) into a checked FeatureLayers.

    ``window``: only those cells of each layer (see the module docstring).
    """
    names = layer_names(context) if names is None else list(dict.fromkeys(names))
    unknown = [n for n in names if n not in _REGISTRY]
    if unknown:
        raise ValueError(f"names: no layer named {', '.join(map(repr, unknown))}; known: {', '.join(_REGISTRY)}")
    layers = {name: _layer(name, columns, voxel_map, context, window) for name in names}  # FeatureLayers checks them
    return FeatureLayers(
        columns.geometry,
        layers,
        columns.observed,
        columns.elevation,  # NaN where unobserved (ColumnLayers' contract)
        columns.color,
        context.now,
        window,
    )


def _layer(name: str, columns: ColumnLayers, voxel_map: Any, context: LayerContext,
           window: GridWindow | None) -> np.ndarray:
    fn = _REGISTRY[name]
    if window is None:
        return fn(columns, voxel_map, context)
    if name in _WINDOWED:
        return fn(columns, voxel_map, context, window=window)
    whole = fn(columns, voxel_map, context)
    if not isinstance(whole, np.ndarray) or whole.shape != columns.geometry.shape:
        return whole  # FeatureLayers names the layer and what is wrong with it
    return whole[window.slices]


register_layer("fringe", lambda c, m, ctx, window=None: features.fringe(c.observed, ctx.options.fringe_closing,
                                                                        window), windowed=True)
register_layer("time", lambda c, m, ctx, window=None: features.time_since_seen(
    c.observed, c.last_seen, ctx.now, window, c.value_range("last_seen")), windowed=True)
register_layer("distance", lambda c, m, ctx, window=None: features.min_distance(
    c.observed, c.min_distance, ctx.options.max_distance, window), windowed=True)
register_layer("elevation", lambda c, m, ctx, window=None: features.elevation(
    c.observed, c.elevation, window, c.value_range("elevation")), windowed=True)
register_layer("view_gain", view_gain.layer, needs=("view", "aoi"))
