"""Report figures are real PNGs showing what they claim (checked by reading pixels back)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from layerpilot.eval.metrics import disk_mask
from layerpilot.eval.pictures.plots import plot_flight_path, plot_layer, plot_metric
from layerpilot.eval.series import MetricSeries
from layerpilot.grid import GridGeometry
from layerpilot.map.columns import ColumnLayers


def _series(scale: float) -> MetricSeries:
    s = MetricSeries(["percent_mapped"])
    for t in range(0, 60, 10):
        s.append(float(t), {"percent_mapped": scale * t})
    return s


def _pixels(path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert image is not None, f"{path} is not a readable image"
    return image


def test_metric_plot_several_behaviors_with_seed_bands(tmp_path) -> None:
    out = plot_metric(
        {"balanced": [_series(1.0), _series(1.2)], "orbit": [_series(0.3)]}, "percent_mapped", tmp_path / "m.png"
    )
    image = _pixels(out)
    assert image.shape[0] > 200 and image.shape[1] > 400
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 20  # lines, band, text: not a blank canvas
    with pytest.raises(ValueError, match="runs"):
        plot_metric({}, "percent_mapped", tmp_path / "x.png")


def test_flight_path_over_color_layer(tmp_path) -> None:
    g = GridGeometry(-50.0, -50.0, 1.0, 100, 100)
    layers = ColumnLayers.empty(g)
    layers.observed[:, :50] = True
    layers.color[:, :50] = (0, 200, 0)  # western half green
    path = np.array([[-40.0, -40.0], [0.0, 0.0], [40.0, 30.0]])
    out = plot_flight_path(layers, path, disk_mask(g, (0.0, 0.0), 30.0), tmp_path / "path.png", title="t")
    bgr = _pixels(out).astype(int)
    green = (bgr[..., 1] > 150) & (bgr[..., 0] < 60) & (bgr[..., 2] < 60)
    red = (bgr[..., 2] > 200) & (bgr[..., 1] < 60) & (bgr[..., 0] < 60)
    yellow = (bgr[..., 2] > 200) & (bgr[..., 1] > 200) & (bgr[..., 0] < 80)
    assert green.sum() > 10_000 and red.sum() > 50 and yellow.sum() > 50
    with pytest.raises(ValueError, match="path_xy"):
        plot_flight_path(layers, path[:, :1], np.ones(g.shape, bool), tmp_path / "x.png")


def test_layer_image(tmp_path) -> None:
    g = GridGeometry(0.0, 0.0, 1.0, 20, 10)
    layers = ColumnLayers.empty(g)
    values = np.tile(np.arange(20, dtype=np.float32), (10, 1))
    image = _pixels(plot_layer(values, layers, tmp_path / "layer.png", "elevation"))
    assert image.std() > 10
    with pytest.raises(ValueError, match="values"):
        plot_layer(values.T, layers, tmp_path / "x.png", "bad")
