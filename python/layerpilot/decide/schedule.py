"""Weight schedules: mission phases that switch the weights by time or by coverage."""

from __future__ import annotations

from layerpilot.decide.behavior import Behavior


class WeightSchedule:
    """The behavior's base weights, then each ``[[schedule]]`` phase in file order once reached.

    Phases latch: once a phase's condition (``after_time`` or ``after_coverage``) has held
    at a tick, it and every phase before it stay passed, even if coverage later dips
    (occupancy can flip). So "explore until 85% observed, then patrol by time" is two
    lines and never flips back.
    """

    def __init__(self, behavior: Behavior) -> None:
        self.behavior = behavior
        self.phase = 0  # 0: base weights; k: schedule[k - 1]

    def weights(self, time: float, coverage: float) -> dict[str, float]:
        for k, phase in enumerate(self.behavior.schedule[self.phase:], start=self.phase + 1):
            reached = (phase.after_time is not None and time >= phase.after_time) or (
                phase.after_coverage is not None and coverage >= phase.after_coverage
            )
            if not reached:
                break
            self.phase = k
        return self.behavior.weights if self.phase == 0 else self.behavior.schedule[self.phase - 1].weights
