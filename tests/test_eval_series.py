"""Metric time series: sampling every 10 simulated seconds, CSV round trip."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerpilot.eval.series import MetricSeries, SeriesSampler


def test_sampler_takes_one_sample_per_interval_at_step_times() -> None:
    sampler = SeriesSampler(["a", "b"], interval=10.0)
    calls = []

    def compute() -> dict[str, float]:
        calls.append(1)
        return {"a": len(calls), "b": float("nan")}

    for step in range(0, 84):  # 0.0 .. 31.5 s in 0.375 s steps
        sampler.maybe_sample(step * 0.375, compute)
    t = sampler.series.column("t")
    np.testing.assert_allclose(t, [0.0, 10.125, 20.25, 30.0])  # first step at or after each multiple of 10
    assert len(calls) == 4  # metrics computed only when due
    np.testing.assert_array_equal(sampler.series.column("a"), [1, 2, 3, 4])


def test_csv_round_trip_keeps_values_and_nan(tmp_path) -> None:
    s = MetricSeries(["percent_mapped", "avg_time_since_observed"])
    s.append(0.0, {"percent_mapped": 0.0, "avg_time_since_observed": float("nan")})
    s.append(10.0, {"percent_mapped": 12.345678901234, "avg_time_since_observed": 3.25})
    path = tmp_path / "metrics.csv"
    s.to_csv(path)
    assert path.read_text().splitlines()[0] == "t,percent_mapped,avg_time_since_observed"
    back = MetricSeries.read_csv(path)
    assert back.names == s.names
    assert back.column("percent_mapped")[1] == 12.345678901234  # repr: exact float round trip
    assert math.isnan(back.column("avg_time_since_observed")[0])
    assert back.last() == {"t": 10.0, "percent_mapped": 12.345678901234, "avg_time_since_observed": 3.25}


def test_series_rejects_bad_input(tmp_path) -> None:
    s = MetricSeries(["a"])
    s.append(1.0, {"a": 1.0})
    with pytest.raises(ValueError, match="t:"):
        s.append(1.0, {"a": 2.0})
    with pytest.raises(ValueError, match="missing"):
        s.append(2.0, {"b": 2.0})
    with pytest.raises(ValueError, match="name"):
        s.column("b")
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n1,2\n")
    with pytest.raises(ValueError, match="bad.csv"):
        MetricSeries.read_csv(bad)
    with pytest.raises(ValueError, match="interval"):
        SeriesSampler(["a"], interval=0.0)
