"""Feature layers: float32 images in [0, 1] on the map's column grid; higher = more interesting.

Built in: ``fringe`` (edge of the known map), ``time`` (time since last seen),
``distance`` (closest observation distance), ``elevation`` (normalised); plus the color
of each column for pictures. More layers plug in through the registry.
"""

from layerpilot.layers.feature_layers import FeatureLayers, check_layer
from layerpilot.layers.registry import (
    LayerContext,
    LayerOptions,
    compute_layers,
    layer_names,
    load_plugins,
    register_layer,
    unregister_layer,
)

__all__ = [
    "LayerContext",
    "LayerOptions",
    "FeatureLayers",
    "check_layer",
    "compute_layers",
    "layer_names",
    "load_plugins",
    "register_layer",
    "unregister_layer",
]
