"""Zenoh sessions on loopback: peers meet at the first one's endpoint, router/client (access control and
logins: test_bus_security.py)."""

from __future__ import annotations

import time

import pytest

from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.config import ConfigError


def received_after(sub_session, key: str, put) -> list[bytes]:
    got: list[bytes] = []
    sub = sub_session.declare_subscriber(key, lambda s: got.append(s.payload.to_bytes()))
    time.sleep(0.5)
    put()
    end = time.monotonic() + 5
    while not got and time.monotonic() < end:
        time.sleep(0.02)
    time.sleep(0.3)  # anything that should not arrive has had time to
    sub.undeclare()
    return got


def test_first_peer_listens_others_connect():
    ep = free_endpoint()
    sessions = [open_session(BusConfig(endpoint=ep)) for _ in range(3)]
    try:
        # the 2nd and 3rd could not take the port: they listen elsewhere and reach each other through the 1st
        assert len(sessions[0].info.peers_zid()) == 2
        got = received_after(sessions[2], "layerpilot/uav1/pose", lambda: sessions[1].put("layerpilot/uav1/pose", b"p"))
        assert got == [b"p"]
    finally:
        for s in sessions:
            s.close()


def test_router_and_clients():
    ep = free_endpoint()
    router = open_session(BusConfig(mode="router", endpoint=ep))
    a, b = (open_session(BusConfig(mode="client", endpoint=ep)) for _ in range(2))
    try:
        assert received_after(b, "layerpilot/*/state", lambda: a.put("layerpilot/uav2/state", b"s")) == [b"s"]
    finally:
        for s in (a, b, router):
            s.close()


def test_bad_endpoint_names_the_key():
    with pytest.raises(ConfigError, match="not a Zenoh locator"):
        BusConfig(endpoint="127.0.0.1:7447")
