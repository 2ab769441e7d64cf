"""What every part of the flight link shares: one lock, the stop and interrupt flags, the waits built
on them, and the reports.

The worker thread and the mission thread touch the same state, so all parts guard it with one
``threading.Condition`` (``cond``) and wake each other through it. Every report goes to ``events``
(a list of strings), the ``on_event`` callback and the ``layerpilot.link`` logger.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from layerpilot.link.errors import LinkError

log = logging.getLogger("layerpilot.link")

WAKE_S = 0.2  # longest single sleep of a wait (see LinkSync.wait)


class LinkSync:
    """The shared lock, flags and report list of one flight link."""

    def __init__(self, on_event: Callable[[str], None] | None = None) -> None:
        self.cond = threading.Condition()
        self.stop = threading.Event()         # close(): the worker ends, every wait returns
        self.interrupted = threading.Event()  # interrupt(): the waits end, the connection stays up
        self.events: list[str] = []
        self.on_event = on_event

    def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Wait for ``predicate`` (False on timeout, close or interrupt) in slices of WAKE_S: the caller
        may be a process's main thread, which must get back to the interpreter for a signal to be handled."""
        deadline = time.monotonic() + timeout
        with self.cond:
            while not (predicate() or self.stop.is_set() or self.interrupted.is_set()):
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self.cond.wait(min(left, WAKE_S))
            return predicate()

    def sleep(self, seconds: float) -> None:
        """Sleep ``seconds``, ended early by close or interrupt."""
        self.wait(lambda: False, seconds)

    def check_interrupted(self, doing: str) -> None:
        if self.interrupted.is_set():
            raise LinkError(f"interrupted while {doing}")

    def report(self, text: str, level: int = logging.WARNING) -> None:
        self.events.append(text)
        log.log(level, "%s", text)
        if self.on_event is not None:
            self.on_event(text)
