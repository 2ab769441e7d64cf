"""Bad input never takes a node down: it is rejected with a reason, counted, and logged once per kind."""

from __future__ import annotations

import logging
import threading
from collections import Counter


class BadMessage(ValueError):
    """A payload that cannot be accepted; ``kind`` groups like failures for counting and logging."""

    def __init__(self, kind: str, reason: str) -> None:
        super().__init__(f"{kind}: {reason}")
        self.kind = kind
        self.reason = reason


class Rejects:
    """Thread-safe counts of rejected messages per (key, kind); the first of each kind is logged."""

    def __init__(self, logger: logging.Logger | None = None) -> None:
        self._log = logger or logging.getLogger("layerpilot.bus")
        self._lock = threading.Lock()
        self.counts: Counter[tuple[str, str]] = Counter()

    def reject(self, key: str, error: BadMessage) -> None:
        with self._lock:
            first = (key, error.kind) not in self.counts
            self.counts[(key, error.kind)] += 1
        if first:
            self._log.warning("rejected message on %s: %s (further ones of this kind are only counted)", key, error)

    @property
    def total(self) -> int:
        with self._lock:
            return sum(self.counts.values())

    def by_kind(self) -> dict[str, int]:
        with self._lock:
            out: Counter[str] = Counter()
            for (_, kind), n in self.counts.items():
                out[kind] += n
            return dict(out)
