"""Metric time series: sampled at a fixed simulated-time interval, stored as CSV."""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

SAMPLE_INTERVAL = 10.0  # simulated seconds between samples, as the issue asks


class MetricSeries:
    """Rows of named float metrics, one per sample time ``t`` (seconds, increasing)."""

    def __init__(self, names: list[str]) -> None:
        if not names or len(set(names)) != len(names) or "t" in names:
            raise ValueError(f"names: need distinct metric names other than 't', got {names}")
        self.names = list(names)
        self.rows: list[list[float]] = []

    def append(self, t: float, values: Mapping[str, float]) -> None:
        if self.rows and not t > self.rows[-1][0]:
            raise ValueError(f"t: samples must be in increasing time, got {t} after {self.rows[-1][0]}")
        missing = set(self.names) - set(values)
        if missing:
            raise ValueError(f"values: missing metrics {sorted(missing)}")
        self.rows.append([float(t)] + [float(values[n]) for n in self.names])

    def __len__(self) -> int:
        return len(self.rows)

    def column(self, name: str) -> np.ndarray:
        """One metric (or ``"t"``) over time as float64."""
        if name != "t" and name not in self.names:
            raise ValueError(f"name: unknown metric {name!r}; have {self.names}")
        i = 0 if name == "t" else 1 + self.names.index(name)
        return np.array([row[i] for row in self.rows], dtype=np.float64)

    def last(self) -> dict[str, float]:
        if not self.rows:
            raise ValueError("the series is empty")
        return dict(zip(["t"] + self.names, self.rows[-1]))

    def to_csv(self, path: str | os.PathLike) -> None:
        """Write ``t`` and each metric as columns; NaN is written as an empty cell."""
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t"] + self.names)
            for row in self.rows:
                w.writerow(["" if math.isnan(v) else repr(v) for v in row])

    @classmethod
    def read_csv(cls, path: str | os.PathLike) -> "MetricSeries":
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
        if not rows or rows[0][:1] != ["t"]:
            raise ValueError(f"path: {Path(path).name} is not a metric series CSV (first column must be 't')")
        series = cls(rows[0][1:])
        for line, row in enumerate(rows[1:], start=2):
            if len(row) != len(rows[0]):
                raise ValueError(f"path: {Path(path).name} line {line} has {len(row)} cells, expected {len(rows[0])}")
            values = [float(v) if v else float("nan") for v in row]
            series.append(values[0], dict(zip(series.names, values[1:])))
        return series


class SeriesSampler:
    """Records metrics at t = 0, interval, 2 * interval, ... of the mission clock.

    The mission loop calls ``maybe_sample`` every step; metrics are computed (the costly
    part) only when a sample is due, and stamped with the step's actual time.
    """

    def __init__(self, names: list[str], interval: float = SAMPLE_INTERVAL) -> None:
        if not interval > 0:
            raise ValueError(f"interval: must be > 0, got {interval}")
        self.interval = float(interval)
        self.series = MetricSeries(names)
        self._next = 0.0

    def due(self, t: float) -> bool:
        return t >= self._next - 1e-9

    def maybe_sample(self, t: float, compute: Callable[[], Mapping[str, float]]) -> bool:
        """Sample if due at time ``t``; returns whether a sample was taken."""
        if not self.due(t):
            return False
        self.series.append(t, compute())
        self.taken(t)
        return True

    def taken(self, t: float) -> None:
        """A sample was taken at ``t`` (its metrics appended by the caller, perhaps later): the next is due
        one interval on."""
        self._next = (math.floor(t / self.interval + 1e-9) + 1) * self.interval
