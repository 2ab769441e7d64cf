"""The layer registry: user layers by name, their checks, and the worked example in docs/layers.md."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from layerpilot.decide import DecisionMaker, load_behavior
from layerpilot.grid import GridGeometry
from layerpilot.layers import LayerContext, compute_layers, layer_names, register_layer, unregister_layer
from layerpilot.map.columns import ColumnLayers

DOCS = Path(__file__).resolve().parents[1] / "docs" / "layers.md"


@pytest.fixture
def cleanup():
    names = set(layer_names())
    yield
    for name in set(layer_names()) - names:
        unregister_layer(name)


def test_a_registered_layer_is_computed_and_checked(cleanup) -> None:
    g = GridGeometry(0.0, 0.0, 1.0, 3, 2)
    cols = ColumnLayers.empty(g)
    register_layer("half", lambda c, m, ctx: np.full(c.geometry.shape, 0.5, np.float32))
    assert "half" in layer_names()
    assert (compute_layers(cols, LayerContext(now=0.0), ["half"])["half"] == 0.5).all()
    with pytest.raises(ValueError, match="already registered"):
        register_layer("half", lambda c, m, ctx: None)
    register_layer("bad_range", lambda c, m, ctx: np.full(c.geometry.shape, 2.0, np.float32))
    with pytest.raises(ValueError, match=r"layer 'bad_range': values must lie in \[0, 1\]"):
        compute_layers(cols, LayerContext(now=0.0), ["bad_range"])
    register_layer("bad_shape", lambda c, m, ctx: np.zeros((5, 5), np.float32))
    with pytest.raises(ValueError, match="layer 'bad_shape': expected float32 array of shape"):
        compute_layers(cols, LayerContext(now=0.0), ["bad_shape"])
    with pytest.raises(ValueError, match="name"):
        register_layer("color", lambda c, m, ctx: None)


def _docs_blocks() -> dict[str, str]:
    """Code blocks of docs/layers.md that start with a '# file: NAME' line."""
    blocks = re.findall(r"```(?:python|toml)\n# file: (\S+)\n(.*?)```", DOCS.read_text(), re.S)
    return dict(blocks)


def test_worked_example_in_the_docs_runs(tmp_path: Path, cleanup) -> None:
    blocks = _docs_blocks()
    assert {"operator_layer.py", "operator.toml"} <= set(blocks)
    for name, text in blocks.items():
        (tmp_path / name).write_text(text)
    behavior = load_behavior(tmp_path / "operator.toml")
    assert behavior.weights["operator"] > 0 and "operator" in layer_names()
    g = GridGeometry(-60.0, -60.0, 1.0, 120, 120)
    cols = ColumnLayers.empty(g)
    home = (5.0, -3.0)
    layers = compute_layers(cols, LayerContext(now=0.0, home=home), behavior.layer_names)
    op = layers["operator"]
    r, c = g.cell_of(*home)
    assert op[r, c] == pytest.approx(1.0, abs=0.02) and op[0, 0] < op[r, c]
    decision = DecisionMaker(behavior, home=home).decide(layers, (home[0], home[1], 40.0), 0.0)
    assert decision.contributions["operator"] > 0 and decision.fallback is None
