"""Zenoh sessions on loopback: peers meet at the first one's endpoint, router/client, access control."""

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


def access_control_example(users_file: str) -> tuple[dict, dict]:
    """The docs/bus.md example: every node but `decide` is denied putting waypoints (router side)."""
    acl = {
        "enabled": True,
        "default_permission": "allow",
        "rules": [{"id": "no-waypoints", "messages": ["put"], "flows": ["ingress"], "permission": "deny",
                   "key_exprs": ["layerpilot/*/waypoint"]}],
        "subjects": [{"id": "not-decide", "usernames": ["link", "depth", "sim", "map-server"]}],
        "policies": [{"rules": ["no-waypoints"], "subjects": ["not-decide"]}],
    }
    transport = {"auth": {"usrpwd": {"user": "router", "password": "router-secret", "dictionary_file": users_file}}}
    return acl, transport


def login(user: str) -> dict:
    return {"auth": {"usrpwd": {"user": user, "password": f"{user}-secret"}}}


def test_access_control_only_decide_publishes_waypoints(tmp_path):
    users = tmp_path / "users.txt"
    users.write_text("".join(f"{u}:{u}-secret\n" for u in ("decide", "link", "depth", "sim", "map-server")))
    acl, transport = access_control_example(str(users))
    ep = free_endpoint()
    router = open_session(BusConfig(mode="router", endpoint=ep, access_control=acl, transport=transport))
    decide, link, sim = (open_session(BusConfig(mode="client", endpoint=ep, transport=login(u)))
                         for u in ("decide", "link", "sim"))
    try:
        key = "layerpilot/uav1/waypoint"
        assert received_after(link, key, lambda: decide.put(key, b"decide")) == [b"decide"]
        assert received_after(decide, key, lambda: link.put(key, b"link")) == []
        assert received_after(link, key, lambda: sim.put(key, b"sim")) == []
        assert received_after(decide, "layerpilot/uav1/pose", lambda: link.put("layerpilot/uav1/pose", b"p")) == [b"p"]
    finally:
        for s in (decide, link, sim, router):
            s.close()


def test_bad_endpoint_names_the_key():
    with pytest.raises(ConfigError, match="not a Zenoh locator"):
        BusConfig(endpoint="127.0.0.1:7447")
