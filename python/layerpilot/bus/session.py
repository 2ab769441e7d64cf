"""Opening a Zenoh session the layerpilot way.

Default: a peer on loopback, multicast scouting off, explicit endpoints. The first node
to start listens on ``tcp/127.0.0.1:7447`` (Zenoh's usual port, so an outside peer can
join the way ROS 2 users expect); later nodes find the port taken, listen on a free one
and connect to the first. ``mode = "router"``/``"client"`` is for several machines.
TLS settings are Zenoh's own, passed through unchanged (so are ``transport.auth`` and
``access_control``, but only with ``security = false``).

``security = true`` (the default) is what `layerpilot up` and `layerpilot router` build the
mission's hub from (bus/security.py: per-node logins, an allow-list, clients only); it also
restricts the endpoints: loopback TCP, or TLS with client certificates and nothing else.
"""

from __future__ import annotations

import ipaddress
import json
import logging
from dataclasses import dataclass, field
from typing import Any, Literal

import zenoh

from layerpilot.config import ConfigError

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
# Topics whose every message matters (a lost cloud is a hole in the map, a lost waypoint a stalled
# drone): the transport blocks instead of dropping when its queue is full. Camera frames and poses
# are streams where only the newest counts, so they keep Zenoh's default (drop).
LOSSLESS_TOPICS = ("cloud", "layers", "decision", "waypoint", "state")
_log = logging.getLogger("layerpilot.bus")


@dataclass(frozen=True)
class BusConfig:
    """The ``[bus]`` table of a mission file."""

    mode: Literal["peer", "router", "client"] = "peer"
    endpoint: str = DEFAULT_ENDPOINT  # the well-known endpoint: listened on by the first peer / the router
    listen: list[str] = field(default_factory=list)  # extra listen endpoints (e.g. tls/0.0.0.0:7448)
    connect: list[str] = field(default_factory=list)  # extra endpoints to connect to
    multicast_scouting: bool = False
    transport: dict[str, Any] = field(default_factory=dict)  # Zenoh "transport" table (TLS certificates, auth)
    access_control: dict[str, Any] = field(default_factory=dict)  # Zenoh "access_control" table, as documented by Zenoh
    security: bool = True  # per-node logins + the mission's allow-list on the hub; false only for debugging
    operator_can_save: bool = False  # the operator's credentials may also query map/save

    def __post_init__(self) -> None:
        for ep in (self.endpoint, *self.listen, *self.connect):
            if "/" not in ep:
                raise ConfigError(f"bus endpoint {ep!r} is not a Zenoh locator like tcp/127.0.0.1:7447")
        if self.security:
            self.check_security()

    def check_security(self) -> None:
        """With ``security`` on: the hub makes logins and the allow-list itself, and the bus is either
        loopback TCP or TLS with client certificates (mutual TLS), never plain TCP beside TLS."""
        off = "or set bus.security = false (debugging only)"
        if self.access_control or "auth" in self.transport:
            raise ConfigError("bus.access_control / bus.transport.auth: with bus.security on, the hub builds the "
                              f"logins and the allow-list itself (docs/bus.md, Security); drop them {off}")
        endpoints = [("bus.endpoint", self.endpoint)] + [(f"bus.{k}", e) for k in ("listen", "connect")
                                                         for e in getattr(self, k)]
        link = self.transport.get("link")
        tls = link.get("tls") if isinstance(link, dict) else None
        tls = tls if isinstance(tls, dict) else {}
        any_tls = any(e.startswith("tls/") for _, e in endpoints)
        for name, ep in endpoints:
            proto = ep.split("/", 1)[0]
            if any_tls and proto != "tls":
                raise ConfigError(f"{name} {ep!r}: a TLS bus has no plain endpoint beside it; make it tls/ {off}")
            if proto not in ("tcp", "tls"):
                raise ConfigError(f"{name} {ep!r}: a secure bus is tcp/ on loopback or tls/ {off}")
            if proto == "tcp" and not is_loopback(ep):
                raise ConfigError(f"{name} {ep!r}: off this machine the bus needs mutual TLS (a tls/ endpoint and "
                                  f"bus.transport.link.tls with enable_mtls = true; docs/bus.md, Security) {off}")
        if any_tls:
            missing = [k for k in ("root_ca_certificate", "enable_mtls") if not tls.get(k)]
            if missing:
                raise ConfigError(f"bus.transport.link.tls: a TLS bus needs client certificates: set "
                                  f"{' and '.join(missing)} (docs/bus.md, Security) {off}")


def is_loopback(endpoint: str) -> bool:
    """Whether a locator's host is this machine only (127.0.0.0/8, ::1, localhost)."""
    address = endpoint.split("/", 1)[-1].split("#", 1)[0].split("?", 1)[0]
    host = address.rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def zenoh_config(cfg: BusConfig, *, listen: list[str], connect: list[str]) -> zenoh.Config:
    """The zenoh.Config of ``cfg`` with the given endpoints (JSON5 inserts, so every key Zenoh knows works)."""
    z = zenoh.Config()
    z.insert_json5("mode", json.dumps(cfg.mode))
    z.insert_json5("scouting/multicast/enabled", json.dumps(cfg.multicast_scouting))
    z.insert_json5("listen/endpoints", json.dumps(listen))
    z.insert_json5("connect/endpoints", json.dumps(connect))
    # Zenoh's shared memory (on by default since eclipse-zenoh 1.6) keeps 20 to 40 MB in every process each
    # time a peer dies (tools/zenoh_restart_leak.py, docs/bus.md); payloads here are plain bytes, which never
    # use it. A mission's bus.transport.shared_memory table can turn it back on.
    z.insert_json5("transport/shared_memory/enabled", "false")
    try:
        for key, value in cfg.transport.items():
            z.insert_json5(f"transport/{key}", json.dumps(value))
        if cfg.access_control:
            z.insert_json5("access_control", json.dumps(cfg.access_control))
    except zenoh.ZError as exc:
        raise ConfigError(f"bus: Zenoh rejected the transport/access_control settings: {exc}") from None
    return z


def open_session(cfg: BusConfig | None = None) -> zenoh.Session:
    """Open a session per ``cfg`` (see the module docstring for who listens and who connects)."""
    cfg = cfg or BusConfig()
    if cfg.mode == "client":
        return zenoh.open(zenoh_config(cfg, listen=[], connect=[cfg.endpoint, *cfg.connect]))
    if cfg.mode == "router":
        return zenoh.open(zenoh_config(cfg, listen=[cfg.endpoint, *cfg.listen], connect=list(cfg.connect)))
    try:
        return zenoh.open(zenoh_config(cfg, listen=[cfg.endpoint, *cfg.listen], connect=list(cfg.connect)))
    except zenoh.ZError as exc:
        if "already in use" not in str(exc).lower():
            raise
    host = cfg.endpoint.rsplit(":", 1)[0]
    _log.debug("%s is taken: listening on a free port and connecting to it", cfg.endpoint)
    return zenoh.open(zenoh_config(cfg, listen=[f"{host}:0", *cfg.listen], connect=[cfg.endpoint, *cfg.connect]))


def publish(session: zenoh.Session, key: str, payload: bytes, lossless: bool | None = None) -> None:
    """Put ``payload`` on ``key`` with the congestion control its topic needs (see LOSSLESS_TOPICS), or
    blocking when ``lossless`` says so (a survey photo played as a camera frame: each one is a picture
    the map needs, not the newest of a stream)."""
    if lossless is None:
        lossless = key.rsplit("/", 1)[-1] in LOSSLESS_TOPICS
    session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK if lossless else None)


def free_endpoint() -> str:
    """A loopback TCP endpoint on a port that is free right now (tests, benchmarks)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"
