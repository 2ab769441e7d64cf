"""What a study reads off a run beyond its final metrics: when the area was covered, how well frames paired.

Time to X % comes from the run's metric series (``percent_mapped`` sampled every 10
simulated seconds), interpolated linearly between the two samples around the crossing; a run
that never reaches X % has NaN there ("never"). The paired-frame ratio is the fraction of
camera frames that found a stereo partner and gave a cloud (``clouds / frames`` of the run's
settings): the share of the flight that mapped anything.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from layerpilot.eval.series import MetricSeries

COVERAGE_MILESTONES = (50.0, 80.0, 90.0)  # percent of the area of interest


def time_to_percent(series: MetricSeries, percent: float) -> float:
    """Mission time (s) at which ``percent_mapped`` first reaches ``percent``; NaN if it never does."""
    if not 0 < percent <= 100:
        raise ValueError(f"percent: must be in (0, 100], got {percent}")
    t, mapped = series.column("t"), series.column("percent_mapped")
    reached = np.flatnonzero(mapped >= percent)
    if len(reached) == 0:
        return math.nan
    i = int(reached[0])
    if i == 0 or not np.isfinite(mapped[i - 1]):
        return float(t[i])
    frac = (percent - mapped[i - 1]) / (mapped[i] - mapped[i - 1])
    return float(t[i - 1] + frac * (t[i] - t[i - 1]))


def paired_ratio(settings: Mapping[str, Any]) -> float:
    """Stereo clouds per camera frame of one run (NaN without frames)."""
    frames = settings.get("frames", 0)
    return float(settings.get("clouds", 0)) / frames if frames else math.nan


def run_milestones(series: MetricSeries, settings: Mapping[str, Any]) -> dict[str, float]:
    """The study's extra columns for one run: time to each coverage milestone, paired ratio, retargets."""
    out = {f"time_to_{p:g}": time_to_percent(series, p) for p in COVERAGE_MILESTONES}
    out["paired_ratio"] = paired_ratio(settings)
    out["retargets"] = float(settings.get("retargets", 0))
    return out


def never_or_spread(values: Sequence[float]) -> str:
    """``mean ± std`` of the runs that reached a milestone, with ``never`` for those that did not."""
    done = [v for v in values if not math.isnan(v)]
    if not done:
        return "never"
    text = f"{np.mean(done):.0f}" + (f" ± {np.std(done, ddof=1):.0f}" if len(done) > 1 else "")
    return text if len(done) == len(values) else f"{text} ({len(values) - len(done)} of {len(values)} never)"
