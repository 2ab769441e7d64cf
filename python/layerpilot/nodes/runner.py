"""What every node process shares: config file loading, logging, and SIGTERM = finish and exit."""

from __future__ import annotations

import faulthandler
import logging
import signal
import threading
from pathlib import Path
from typing import Any

from layerpilot.bus.session import BusConfig
from layerpilot.config import ConfigError, from_dict, load_toml


def load_tables(path: str | Path | None) -> dict[str, Any]:
    return load_toml(path) if path else {}


def bus_config(tables: dict[str, Any], endpoint: str | None, mode: str | None = None) -> BusConfig:
    data = dict(tables.get("bus", {}))
    if endpoint:
        data["endpoint"] = endpoint
    if mode:
        data["mode"] = mode
    return from_dict(BusConfig, data, "bus")


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


__all__ = ["ConfigError", "WAKE_PERIOD", "bus_config", "load_tables", "stop_event", "wait_for_stop"]
