"""What a decision returns: the waypoint and why (every term at the chosen cell)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Candidate:
    waypoint: tuple[float, float, float]  # map frame, cell centre at the waypoint altitude
    cell: tuple[int, int]  # (row, col)
    score: float  # A3 at the cell (without noise)


@dataclass(frozen=True)
class Decision:
    """The next waypoint with its explanation.

    ``contributions`` holds w_i * F_i per weighted layer at the cell (their sum is
    ``aggregate`` = A0); ``zone`` (Z), ``preference`` (P) and ``history`` (H) are the
    multipliers, so ``score`` = A0 * Z * P * H. ``fallback`` is None for a normal pick,
    else the rule used when nothing scored above zero (see docs/decide.md).
    """

    time: float
    waypoint: tuple[float, float, float]
    cell: tuple[int, int]
    score: float
    contributions: dict[str, float]
    aggregate: float
    zone: float
    preference: float
    history: float
    weights: dict[str, float]
    coverage: float  # fraction of the area of interest observed
    runner_up: Candidate | None = None
    fallback: str | None = None
    retargeted: bool = False
    intermediates: dict[str, np.ndarray] | None = field(default=None, repr=False, compare=False)

    def explain(self) -> str:
        """One line a person can read: where, how much, and from what."""
        terms = " + ".join(f"{k} {v:.3f}" for k, v in self.contributions.items())
        how = f"fallback {self.fallback}" if self.fallback else ("retarget" if self.retargeted else "best")
        x, y, z = self.waypoint
        return (f"t={self.time:.1f}s {how}: ({x:.1f}, {y:.1f}, {z:.1f}) score {self.score:.4f} = "
                f"A0 {self.aggregate:.4f} [{terms or '0'}] * Z {self.zone:.0f} * P {self.preference:.3f} "
                f"* H {self.history:.3f}; coverage {100 * self.coverage:.1f}%")

    def to_dict(self) -> dict:
        """JSON-ready (decisions.jsonl, the bus): everything except the images."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k not in ("intermediates", "runner_up")}
        out["runner_up"] = None if self.runner_up is None else vars(self.runner_up).copy()
        return out
