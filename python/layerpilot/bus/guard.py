"""Subscriber callbacks that can't be killed by bad input: decode, reject-and-count, or hand over."""

from __future__ import annotations

from typing import Any, Callable

import zenoh

from layerpilot.bus.reject import BadMessage, Rejects


def guarded(decode: Callable[[bytes], Any], handle: Callable[[Any, str], None], rejects: Rejects,
            supervisor: Any = None) -> Callable[[zenoh.Sample], None]:
    """A Zenoh sample callback: ``handle(decode(payload), key)``; BadMessage is counted, not raised.

    With a ``supervisor`` (``nodes.supervise.Supervisor``) every accepted input is timed
    (``heard``) and an unexpected exception in ``handle`` is counted and logged with its
    traceback instead of vanishing in the transport's thread.
    """

    def callback(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            msg = decode(sample.payload.to_bytes())
        except BadMessage as exc:
            rejects.reject(key, exc)
            return
        if supervisor is None:
            handle(msg, key)
            return
        supervisor.heard(key)
        try:
            handle(msg, key)
        except BadMessage as exc:
            rejects.reject(key, exc)
        except Exception as exc:
            supervisor.error(f"callback {key}", exc)

    return callback


def query_params(query: zenoh.Query) -> dict[str, str]:
    """The selector parameters of a query (``?x=1;y=2``) as a dict of strings."""
    return parse_params(str(query.parameters))


def parse_params(text: str) -> dict[str, str]:
    return dict(item.partition("=")[::2] for item in text.split(";") if item)
