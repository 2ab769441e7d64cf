"""Secure by default, over real Zenoh sessions on loopback: the mission's hub admits only its users,
each may publish only its own keys, the operator reads but does not steer; mutual TLS between machines."""

from __future__ import annotations

import json
import shutil
import stat
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import zenoh

from layerpilot.bus.keys import Keys
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.security import (JoinRefused, access_control, client_endpoint, grants, load_credentials,
                                     open_hub, open_node_session)
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.config import ConfigError
from layerpilot.missionfile import Mission
from layerpilot.mission.map_service import MapServiceConfig
from layerpilot.nodes.map_server import MapServer

K, K2 = Keys("uav1"), Keys("uav2")


def deliveries(cases: list[tuple[zenoh.Session, str, Callable[[], None]]], settle: float = 0.5) -> list[list[bytes]]:
    """What each (subscriber, key, put) subscription receives when all the puts run at once: it waits up to
    3 s until every subscription has received something (so as long for what should not come), then 0.3 s."""
    got: list[list[bytes]] = [[] for _ in cases]
    subs = [session.declare_subscriber(key, lambda sample, g=g: g.append(sample.payload.to_bytes()))
            for (session, key, _), g in zip(cases, got)]
    time.sleep(settle)
    for _, _, put in cases:
        put()
    end = time.monotonic() + 3
    while not all(got) and time.monotonic() < end:
        time.sleep(0.02)
    time.sleep(0.3)
    for sub in subs:
        sub.undeclare()
    return got


def delivered(subscriber_session, key: str, put, settle: float = 0.5) -> list[bytes]:
    """What a subscription on ``key`` receives when ``put()`` runs (waits for what should not come too)."""
    return deliveries([(subscriber_session, key, put)], settle)[0]


@pytest.fixture
def mission_bus(tmp_path):
    """A hub for vehicles uav1 and uav2 on a free loopback port; ``join(user)`` logs in as that user."""
    cfg = BusConfig(endpoint=free_endpoint())
    hub, secrets = open_hub(cfg, tmp_path / "bus-secrets", ["uav1", "uav2"])
    sessions = []

    def join(user: str) -> zenoh.Session:
        sessions.append(open_node_session(cfg, secrets.credentials_file(user)))
        return sessions[-1]

    yield cfg, secrets, join
    for s in reversed(sessions):
        s.close()
    hub.close()


def test_secrets_are_private_files_and_reused(tmp_path, mission_bus):
    cfg, secrets, join = mission_bus
    d = secrets.directory
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    users = set(grants(["uav1", "uav2"]))
    assert users == {"map-server", "operator"} | {f"{r}-{v}" for r in ("sim", "camera", "link", "depth", "decide")
                                                   for v in ("uav1", "uav2")}
    for f in [secrets.dictionary, secrets.acl_file] + [secrets.credentials_file(u) for u in users]:
        assert stat.S_IMODE(f.stat().st_mode) == 0o600, f
    lines = secrets.dictionary.read_text().splitlines()
    assert sorted(ln.split(":")[0] for ln in lines) == sorted(users)
    assert len({ln.split(":")[1] for ln in lines}) == len(users)  # a password per user
    assert json.loads(secrets.acl_file.read_text())["default_permission"] == "deny"
    before = secrets.credentials_file("decide-uav1").read_text()
    open_hub(BusConfig(endpoint=free_endpoint()), d, ["uav1"])[0].close()  # a restart keeps the passwords
    assert secrets.credentials_file("decide-uav1").read_text() == before
    assert "uav2" not in secrets.dictionary.read_text()  # but only the mission's users may log in
    secrets.credentials_file("decide-uav1").chmod(0o644)
    with pytest.raises(ConfigError, match="open to other users"):
        load_credentials(secrets.credentials_file("decide-uav1"))


def test_outside_peer_without_credentials_cannot_join_nor_deliver_a_waypoint(mission_bus, tmp_path):
    cfg, secrets, join = mission_bus
    link = join("link-uav1")
    # an outside peer the way the finding's attacker joined (plain peer, the mission's endpoint) ...
    outsider = open_session(BusConfig(endpoint=cfg.endpoint, security=False))
    try:
        assert list(outsider.info.routers_zid()) == [] and list(outsider.info.peers_zid()) == []
        assert delivered(link, K.waypoint, lambda: outsider.put(K.waypoint, b"fly away")) == []
    finally:
        outsider.close()
    # ... as a client without a login, and with a wrong password: refused outright
    with pytest.raises(zenoh.ZError):
        zenoh.open(_client_without_login(cfg.endpoint))
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"user": "decide-uav1", "password": "guess"}))
    wrong.chmod(0o600)
    with pytest.raises(JoinRefused, match="decide-uav1"):
        open_node_session(cfg, wrong)


def _client_without_login(endpoint: str) -> zenoh.Config:
    z = zenoh.Config()
    z.insert_json5("mode", '"client"')
    z.insert_json5("scouting/multicast/enabled", "false")
    z.insert_json5("connect/endpoints", json.dumps([endpoint]))
    return z


def test_each_node_publishes_only_its_own_keys(mission_bus):
    cfg, secrets, join = mission_bus
    decide, link, depth, operator = join("decide-uav1"), join("link-uav1"), join("depth-uav1"), join("operator")
    decide2 = join("decide-uav2")
    cases = {  # (subscriber, key, publisher, payload) -> delivered?
        # decide steers its own vehicle; nobody else does, and decide cannot steer the other one
        (link, K.waypoint, decide, b"wp"): True,
        (operator, K.waypoint, link, b"link"): False,
        (operator, K.waypoint, depth, b"depth"): False,
        (link, K.waypoint, operator, b"op"): False,
        (operator, K2.waypoint, decide, b"uav2"): False,
        # the pose is the link's: decide's credentials cannot spoof it
        (decide, K.pose, link, b"pose"): True,
        (operator, K.pose, decide, b"spoof"): False,
        # a node is delivered only what it reads: depth reads camera frames and the pose stream, not waypoints
        (depth, K.waypoint, decide, b"wp2"): False,
        (depth, K.pose, link, b"pose2"): True,
        (decide, K.cloud, depth, b"c"): False,  # decide does not read clouds
        (operator, K.cloud, depth, b"c2"): True,
        # decide reads every vehicle's decisions (to keep away from the others' targets)
        (decide, K2.decision, decide2, b"d2"): True,
    }
    got = deliveries([(sub, key, lambda p=pub, k=key, x=payload: p.put(k, x)) for sub, key, pub, payload in cases])
    wrong = [payload for ((_, _, _, payload), want), g in zip(cases.items(), got) if (payload in g) != want]
    assert not wrong, f"delivered against the allow-list (or refused though allowed): {wrong}"


def map_server(session, tmp_path: Path) -> MapServer:
    cfg = Mission(vehicles=["uav1", "uav2"], map_server=MapServiceConfig(
        resolution=0.5, layers_rate=1.0, window=(-10.0, -10.0, 40, 40), snapshot=str(tmp_path / "map.ot"),
        snapshot_period=3600.0))
    server = MapServer(session, cfg)
    server.start()
    return server


def query(session, selector: str) -> list:
    return list(session.get(selector, timeout=2.0))


@pytest.mark.parametrize("can_save", [False, True])
def test_operator_reads_but_saves_only_when_allowed(tmp_path, can_save):
    cfg = BusConfig(endpoint=free_endpoint(), operator_can_save=can_save)
    hub, secrets = open_hub(cfg, tmp_path / "secrets", ["uav1"])
    server_session = open_node_session(cfg, secrets.credentials_file("map-server"))
    operator = open_node_session(cfg, secrets.credentials_file("operator"))
    decide = open_node_session(cfg, secrets.credentials_file("decide-uav1"))
    server = map_server(server_session, tmp_path)
    try:
        time.sleep(0.5)
        stats = query(operator, K.service("stats"))
        assert len(stats) == 1 and pb.MapStats.FromString(stats[0].ok.payload.to_bytes()).resolution == 0.5
        assert len(query(operator, K.service("layers") + "?x=-10;y=-10;w=8;h=8")) == 1
        assert len(query(decide, K.service("layers") + "?x=-10;y=-10;w=8;h=8")) == 1  # decide may ask for layers
        assert query(decide, K.service("stats")) == []  # ... and nothing else
        assert query(decide, K.service("save")) == []
        saved = query(operator, K.service("save"))
        assert (len(saved) == 1 and saved[0].ok is not None) is can_save
        assert (tmp_path / "map.ot").exists() is can_save
        # a wildcard query does not slip past the allow-list to map/save
        (tmp_path / "map.ot").unlink(missing_ok=True)
        query(operator, "layerpilot/uav1/map/*")
        query(operator, "layerpilot/**")
        time.sleep(0.3)
        assert not (tmp_path / "map.ot").exists()
        # the operator publishes nothing, and a layer set it forges reaches no one (the map server's own
        # layer sets, published from the start for every mission vehicle, do)
        assert b"forged" not in delivered(decide, K.layers, lambda: operator.put(K.layers, b"forged"))
        assert server.queries_answered == 3 + can_save
    finally:
        server.stop()
        for s in (decide, operator, server_session, hub):
            s.close()


def test_credentials_need_a_file_made_by_up(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_credentials(tmp_path / "nope.json")


def test_secure_bus_endpoints():
    BusConfig()  # loopback TCP: fine
    with pytest.raises(ConfigError, match="off this machine the bus needs mutual TLS"):
        BusConfig(endpoint="tcp/0.0.0.0:7447")
    with pytest.raises(ConfigError, match="needs client certificates: set root_ca_certificate and enable_mtls"):
        BusConfig(endpoint="tls/0.0.0.0:7447")
    tls = {"link": {"tls": {"root_ca_certificate": "ca.pem", "enable_mtls": True}}}
    with pytest.raises(ConfigError, match="no plain endpoint beside it"):
        BusConfig(endpoint="tls/0.0.0.0:7447", listen=["tcp/127.0.0.1:7448"], transport=tls)
    with pytest.raises(ConfigError, match="builds the logins and the allow-list itself"):
        BusConfig(access_control={"enabled": True})
    BusConfig(endpoint="tls/0.0.0.0:7447", transport=tls)
    BusConfig(endpoint="tcp/0.0.0.0:7447", security=False)  # debugging only
    assert client_endpoint("tls/0.0.0.0:7447") == "tls/localhost:7447"
    assert client_endpoint("tcp/127.0.0.1:7447") == "tcp/127.0.0.1:7447"


def test_access_control_is_an_allow_list():
    acl = access_control(grants(["uav1"]))
    assert acl["enabled"] and acl["default_permission"] == "deny"
    assert {r["permission"] for r in acl["rules"]} == {"allow"}
    pub = {r["id"]: r["key_exprs"] for r in acl["rules"] if r["messages"] == ["put"] and r["flows"] == ["ingress"]}
    assert pub["decide-uav1/publish"] == ["layerpilot/uav1/waypoint", "layerpilot/uav1/decision",
                                          "layerpilot/uav1/state", "layerpilot/uav1/health/decide"]
    assert pub["link-uav1/publish"] == ["layerpilot/uav1/pose", "layerpilot/uav1/health/link"]
    assert pub["depth-uav1/publish"] == ["layerpilot/uav1/cloud", "layerpilot/uav1/health/depth"]
    assert pub["sim-uav1/publish"] == ["layerpilot/uav1/camera", "layerpilot/uav1/health/sim"]
    assert pub["map-server/publish"] == ["layerpilot/uav1/layers", "layerpilot/uav1/health/map-server"]
    assert "operator/publish" not in pub
    queries = {r["id"]: r["key_exprs"] for r in acl["rules"] if r["messages"] == ["query"] and r["flows"] == ["ingress"]}
    assert queries == {"decide-uav1/query": ["layerpilot/uav1/map/layers"],
                       "operator/query": ["layerpilot/*/map/stats", "layerpilot/*/map/layers",
                                          "layerpilot/*/map/voxels", "layerpilot/*/map/octree",
                                          "layerpilot/*/decide/aggregates"]}
    answers = {r["id"]: r["key_exprs"] for r in acl["rules"] if r["messages"] == ["declare_queryable", "reply"]}
    assert answers["decide-uav1/answer"] == ["layerpilot/uav1/decide/aggregates"]  # its own vehicle's only
    assert set(answers) == {"decide-uav1/answer", "map-server/answer"}


# --- mutual TLS ---------------------------------------------------------------------------------


def make_pki(work: Path) -> Path:
    """Run docs/bus.md's openssl commands as written (in ``work``), then make a stranger's CA and
    client certificate; returns the runs/pki directory."""
    doc = (Path(__file__).resolve().parents[1] / "docs" / "bus.md").read_text()
    start = doc.index("mkdir -p runs/pki")
    subprocess.run(["bash", "-euc", doc[start:doc.index("```", start)]], cwd=work, check=True, capture_output=True)
    d = work / "runs" / "pki"
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    for args in (["req", "-x509", *ec, "-days", "30", "-subj", "/CN=stranger CA", "-keyout", "sca.key", "-out", "sca.pem"],
                 ["req", *ec, "-subj", "/CN=stranger", "-keyout", "stranger.key", "-out", "stranger.csr"],
                 ["x509", "-req", "-in", "stranger.csr", "-CA", "sca.pem", "-CAkey", "sca.key", "-CAcreateserial",
                  "-days", "30", "-extfile", "client.ext", "-out", "stranger.pem"]):
        subprocess.run(["openssl", *args], cwd=d, check=True, capture_output=True)
    return d


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs Debian's openssl to make certificates")
def test_mutual_tls_hub_refuses_clients_without_a_certificate(tmp_path):
    pki = make_pki(tmp_path)
    assert all(stat.S_IMODE(k.stat().st_mode) == 0o600 for k in pki.glob("*.key"))
    port = free_endpoint().rsplit(":", 1)[1]

    def tls(cert: str | None) -> dict:
        t = {"root_ca_certificate": str(pki / "ca.pem"), "enable_mtls": True,
             "listen_certificate": str(pki / "hub.pem"), "listen_private_key": str(pki / "hub.key")}
        if cert:
            t |= {"connect_certificate": str(pki / f"{cert}.pem"), "connect_private_key": str(pki / f"{cert}.key")}
        return {"link": {"tls": t}}

    hub_cfg = BusConfig(endpoint=f"tls/localhost:{port}", transport=tls(None))
    hub, secrets = open_hub(hub_cfg, tmp_path / "secrets", ["uav1"])
    sessions = []
    try:
        def join(user: str, cert: str | None) -> zenoh.Session:
            sessions.append(open_node_session(BusConfig(endpoint=f"tls/localhost:{port}", transport=tls(cert)),
                                              secrets.credentials_file(user)))
            return sessions[-1]

        link, decide = join("link-uav1", "ground"), join("decide-uav1", "drone1")
        assert delivered(link, K.waypoint, lambda: decide.put(K.waypoint, b"wp")) == [b"wp"]
        with pytest.raises(JoinRefused):  # the right password but no client certificate
            join("decide-uav1", None)
        with pytest.raises(JoinRefused):  # a certificate from another CA
            join("decide-uav1", "stranger")
        # plain TCP on the TLS port: not even a TLS handshake
        plain = BusConfig(endpoint=f"tcp/127.0.0.1:{port}", security=False)
        with pytest.raises(JoinRefused):
            open_node_session(plain, secrets.credentials_file("decide-uav1"))
        # a certificate but no login: still refused (the allow-list needs a user name)
        with pytest.raises(zenoh.ZError):
            z = _client_without_login(f"tls/localhost:{port}")
            for k, v in tls("ground")["link"]["tls"].items():
                z.insert_json5(f"transport/link/tls/{k}", json.dumps(v))
            sessions.append(zenoh.open(z))
    finally:
        for s in reversed(sessions):
            s.close()
        hub.close()


def test_router_command_is_a_secured_hub(tmp_path):
    """`layerpilot router` (several machines, nodes started by hand) makes the same logins and allow-list."""
    from conftest import cli_process

    ep = free_endpoint()
    mission = tmp_path / "m.toml"
    mission.write_text('vehicles = ["uav1"]\n')
    with cli_process("router", "--config", str(mission), "--endpoint", ep, "--secrets", str(tmp_path / "s")) as p:
        ready = json.loads(p.stdout.readline())
        assert ready["status"] == "ready" and ready["secrets"] == str(tmp_path / "s")
        cfg = BusConfig(endpoint=ep)
        link = open_node_session(cfg, tmp_path / "s" / "link-uav1.json")
        decide = open_node_session(cfg, tmp_path / "s" / "decide-uav1.json")
        try:
            assert delivered(link, K.waypoint, lambda: decide.put(K.waypoint, b"wp")) == [b"wp"]
            assert delivered(decide, K.waypoint, lambda: link.put(K.waypoint, b"no")) == []
            with pytest.raises(zenoh.ZError):
                zenoh.open(_client_without_login(ep))
        finally:
            link.close()
            decide.close()
        p.terminate()
        assert p.wait(timeout=15) == 0


def test_the_documented_operator_lines_join_a_mission(tmp_path):
    """docs/bus.md's few lines for an outside eclipse-zenoh program, run as written (paths swapped)."""
    doc = (Path(__file__).resolve().parents[1] / "docs" / "bus.md").read_text()
    start = doc.index("import zenoh  # join a running mission as the operator")
    code = doc[start:doc.index("```", start)]
    cfg = BusConfig(endpoint=free_endpoint())
    hub, secrets = open_hub(cfg, tmp_path / "secrets", ["uav1"])
    server_session = open_node_session(cfg, secrets.credentials_file("map-server"))
    server = map_server(server_session, tmp_path)
    scope: dict = {}
    try:
        exec(code.replace("runs/bus-secrets/operator.json", str(secrets.credentials_file("operator")))
             .replace("tcp/127.0.0.1:7447", cfg.endpoint), scope)
        assert pb.MapStats.FromString(scope["stats"].ok.payload.to_bytes()).resolution == 0.5
    finally:
        if "session" in scope:
            scope["session"].close()
        server.stop()
        server_session.close()
        hub.close()
