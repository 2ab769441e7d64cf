"""What every node process shares: its bus settings, logging, and SIGTERM = finish and exit."""

from __future__ import annotations

import dataclasses
import faulthandler
import logging
import signal
import threading

from layerpilot.bus.session import BusConfig
from layerpilot.config import ConfigError


def bus_config(bus: BusConfig, endpoint: str | None, mode: str | None = None) -> BusConfig:
    """The mission's bus settings with the command line's ``--endpoint`` (and a router's mode)."""
    changes = {k: v for k, v in (("endpoint", endpoint), ("mode", mode)) if v}
    try:
        return dataclasses.replace(bus, **changes)
    except ConfigError as exc:
        raise ConfigError(f"--endpoint {endpoint!r}: {exc}") from None


STUCK_AFTER = 10.0  # s after SIGTERM: dump every thread's stack to stderr
WAKE_PERIOD = 0.2  # s: how often a waiting main thread gets back to the interpreter


def stop_event() -> threading.Event:
    """An event set by SIGTERM or SIGINT: the node finishes its current message, then exits."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    stop = threading.Event()

    def on_signal(*_: object) -> None:
        stop.set()
        faulthandler.dump_traceback_later(STUCK_AFTER, exit=False)  # if stopping hangs, the log says where

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, on_signal)
    return stop


def wait_for_stop(stop: threading.Event) -> None:
    """Block the main thread until ``stop`` is set, waking every WAKE_PERIOD.

    The kernel may deliver SIGTERM to any thread of the process, e.g. one of Zenoh's; Python
    then runs the handler only when the main thread comes back to the interpreter, which a
    wait without a timeout never does: the node would hang until killed.
    """
    while not stop.wait(WAKE_PERIOD):
        pass


__all__ = ["WAKE_PERIOD", "bus_config", "stop_event", "wait_for_stop"]
