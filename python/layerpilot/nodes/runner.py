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


__all__ = ["ConfigError", "bus_config", "load_tables", "stop_event"]
