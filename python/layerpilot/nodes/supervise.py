"""Supervised worker loops: no thread of a node dies in silence.

Every worker loop of a node runs under one :class:`Supervisor`. An unexpected exception in
an iteration is logged once per kind with its traceback, counted, and the loop goes on with
the next message. A loop that cannot go on (``MemoryError``, or ``MAX_FAILURES_IN_A_ROW``
failing iterations) marks the node failed: its main thread then exits non-zero so that
``layerpilot up`` restarts it. Each loop beats a heartbeat at every iteration (workers wait
with timeouts, so an idle loop still beats); a loop whose heartbeat is older than
``STALL_AFTER`` is stalled, which also fails the node. The node's status lines carry the
age of every loop's heartbeat and of the last input on every key; a :class:`HealthPublisher`
puts the same dict on the node's health key for the operator's view and recordings.
"""

from __future__ import annotations

import logging
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable

import zenoh

from layerpilot.bus import keys
from layerpilot.bus.messages import NodeHealth, encode_health
from layerpilot.bus.session import publish

MAX_FAILURES_IN_A_ROW = 50  # failing iterations without one good one: the loop cannot go on
STALL_AFTER = 30.0  # s without a heartbeat: the loop is stuck
FATAL = (MemoryError, RecursionError)


class Supervisor:
    """Runs a node's worker loops, keeps their heartbeats and input ages, and knows when the node failed."""

    def __init__(self, log: logging.Logger) -> None:
        self.log = log
        self.failed = threading.Event()
        self.failure = ""  # one line: why the node cannot go on
        self.errors: Counter[str] = Counter()  # "loop: ExceptionType" -> count
        self._beats: dict[str, float] = {}
        self._inputs: dict[str, float] = {}
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []

    # --- inputs and heartbeats ------------------------------------------------------------

    def heard(self, key: str) -> None:
        """An input arrived on ``key`` (called from the transport's callbacks)."""
        now = time.monotonic()
        with self._lock:
            self._inputs[key] = now

    def beat(self, loop: str) -> None:
        with self._lock:
            self._beats[loop] = time.monotonic()

    def stalled(self) -> list[str]:
        now = time.monotonic()
        with self._lock:
            return [name for name, t in self._beats.items() if now - t > STALL_AFTER]

    def status(self) -> dict:
        """Ages in seconds (one decimal) of each loop's heartbeat and of the last input per key."""
        now = time.monotonic()
        with self._lock:
            beats = {name: round(now - t, 1) for name, t in self._beats.items()}
            inputs = {key: round(now - t, 1) for key, t in self._inputs.items()}
            errors = sum(self.errors.values())
        return {"loops": beats, "inputs": inputs, "errors": errors}

    # --- loops ----------------------------------------------------------------------------

    def start(self, name: str, iteration: Callable[[], bool]) -> threading.Thread:
        """Run ``iteration()`` again and again in a thread until it returns False (the loop's normal end)."""
        thread = threading.Thread(target=self._run, args=(name, iteration), name=name, daemon=True)
        self.beat(name)
        thread.start()
        self._threads.append(thread)
        return thread

    def _run(self, name: str, iteration: Callable[[], bool]) -> None:
        in_a_row = 0
        while True:
            self.beat(name)
            try:
                if iteration() is False:
                    break
                in_a_row = 0
            except FATAL as exc:
                self.fail(f"{name}: {type(exc).__name__}: {exc}")
                break
            except Exception as exc:  # the next message may be fine: count, log once per kind, go on
                in_a_row += 1
                self.error(name, exc)
                if in_a_row >= MAX_FAILURES_IN_A_ROW:
                    self.fail(f"{name}: {in_a_row} failures in a row, the last: {type(exc).__name__}: {exc}")
                    break
        with self._lock:
            self._beats.pop(name, None)  # a loop that ended normally is not stalled

    def error(self, loop: str, exc: BaseException) -> None:
        """Count an unexpected exception; the first of each kind is logged with its traceback."""
        kind = f"{loop}: {type(exc).__name__}"
        with self._lock:
            first = kind not in self.errors
            self.errors[kind] += 1
        if first:
            self.log.error("unexpected error in %s (further ones of this kind are only counted):\n%s", loop,
                           "".join(traceback.format_exception(exc)).rstrip())

    def fail(self, reason: str) -> None:
        """The node cannot go on: say why once; the main thread exits non-zero."""
        if not self.failed.is_set():
            self.failure = reason
            self.log.critical("node failed: %s", reason)
            self.failed.set()

    def join(self, timeout: float | None = None) -> None:
        for t in self._threads:
            t.join(timeout)


class HealthPublisher:
    """A node's status on the bus, ``layerpilot/<vehicle>/health/<node>``: what its status line prints.

    The map server, one for all vehicles, puts its own on every vehicle's key (a view follows one
    vehicle). A status that cannot be sent (a value JSON refuses, a closed session) is counted and
    logged once per kind; the node goes on.
    """

    def __init__(self, session: zenoh.Session, node: str, vehicles: list[str], log: logging.Logger) -> None:
        self.session, self.node, self.log = session, node, log
        self.keys = {v: keys.Keys(v).health(node) for v in vehicles}
        self.started = time.monotonic()
        self.sent = 0
        self.failed: Counter[str] = Counter()

    def publish(self, status: dict) -> None:
        uptime = time.monotonic() - self.started
        for vehicle, key in self.keys.items():
            try:
                publish(self.session, key, encode_health(NodeHealth(vehicle, self.node, uptime, status)))
                self.sent += 1
            except (ValueError, TypeError, zenoh.ZError) as exc:
                kind = type(exc).__name__
                if not self.failed[kind]:
                    self.log.warning("health: cannot send the status on %s (further ones are only counted): %s",
                                     key, exc)
                self.failed[kind] += 1
