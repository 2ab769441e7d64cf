"""Secure by default: per-node credentials, the mission's allow-list, mutual TLS between machines.

With ``bus.security = true`` (the default) the mission's hub (`layerpilot up`, or `layerpilot
router` for nodes started by hand) is a Zenoh **router** that

- admits only sessions that log in with a user name and password from its dictionary (Zenoh's
  ``transport/auth/usrpwd``): one user per node (``decide-uav1``, ``map-server``, ...) plus
  ``operator``, generated into the mission's secrets directory;
- enforces Zenoh's ``access_control`` as an **allow-list** (``default_permission = "deny"``): each
  user may put, subscribe, query and answer only what its role needs (``grants``).

Every node is a Zenoh **client** of the hub: it opens no listening socket, so nothing reaches it
except through the hub's filters. Off the machine the bus is TLS only, with client certificates
(``BusConfig.check_security``).

The secrets directory (mode 0700; every file 0600):

- ``<user>.json``: ``{"user": ..., "password": ...}``, exactly Zenoh's ``transport/auth/usrpwd``
  table; kept across runs (delete the directory to rotate every password);
- ``users.txt``: the hub's dictionary (``user:password`` lines), rewritten at each start from the
  mission's users only;
- ``access_control.json``: the allow-list the hub enforces, written for reading.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import secrets as _random
import stat
from dataclasses import dataclass
from pathlib import Path

import zenoh

from layerpilot.bus import keys
from layerpilot.bus.session import BusConfig, open_session, zenoh_config
from layerpilot.config import ConfigError

_log = logging.getLogger("layerpilot.bus")
OPERATOR = "operator"
VEHICLE_ROLES = ("sim", "camera", "link", "depth", "decide")
MAP_SERVER = "map-server"
OPERATOR_QUERIES = ("stats", "layers", "voxels", "octree")  # read-only map services; "save" only if allowed


@dataclass(frozen=True)
class Grant:
    """What one user may do on the bus; everything else is denied by the hub."""

    publish: tuple[str, ...] = ()  # keys it may put
    subscribe: tuple[str, ...] = ()  # key expressions it may subscribe to (and be delivered puts on)
    query: tuple[str, ...] = ()  # key expressions it may query (and be delivered replies on)
    answer: tuple[str, ...] = ()  # key expressions it may serve (declare a queryable, get queries, reply)
    announce: tuple[str, ...] = ()  # liveliness tokens it may declare (rmw_zenoh's ROS 2 graph)
    watch: tuple[str, ...] = ()  # liveliness tokens it may see (subscribe to and query)


def node_user(role: str, vehicle: str | None = None) -> str:
    """The bus user of a node: ``map-server``, ``decide-uav1``, ..."""
    return role if vehicle is None else f"{role}-{keys.check_vehicle(vehicle)}"


def grants(vehicles: list[str], operator_can_save: bool = False, photos: bool = False,
           ros2: tuple[int, str] | None = None) -> dict[str, Grant]:
    """Every user of a mission and what it may do (the one place that says who talks to whom).

    ``photos``: the camera plays a photo folder and publishes its photos' poses (there is no link node).
    ``ros2``: (domain id, namespace) of the ROS 2 bridges: each may put under ``<domain>/<namespace>/`` and
    announce itself in rmw_zenoh's graph; the operator (a ROS 2 tool logging in as it) may read them."""
    services = tuple(f"{keys.PREFIX}/*/map/{name}" for name in keys.SERVICES)
    out = {MAP_SERVER: Grant(publish=tuple(key for v in vehicles for key in (keys.Keys(v).layers,
                                                                             keys.Keys(v).health(MAP_SERVER))),
                             subscribe=(keys.all_vehicles("cloud"), keys.all_vehicles("pose")), answer=services)}
    for v in vehicles:  # every node also puts its own health key, nothing else of another node's
        k = keys.Keys(v)
        out[node_user("sim", v)] = Grant(publish=(k.camera, k.health("sim")), subscribe=(k.pose,))  # pose: camera-only
        out[node_user("camera", v)] = Grant(publish=(k.camera, k.health("camera")) + ((k.pose,) if photos else ()),
                                            subscribe=(k.pose,))  # a real camera; a photo folder's is the telemetry
        out[node_user("link", v)] = Grant(publish=(k.pose, k.health("link")),
                                          subscribe=(k.waypoint, k.state))  # state: battery RTL
        out[node_user("depth", v)] = Grant(publish=(k.cloud, k.health("depth")),
                                           subscribe=(k.camera, k.pose))  # pose: the camera clock's offset
        out[node_user("decide", v)] = Grant(publish=(k.waypoint, k.decision, k.state, k.health("decide")),
                                            subscribe=(k.layers, k.pose, keys.all_vehicles("decision")),
                                            query=(k.service("layers"),), answer=(k.aggregates,))
    ros_topics, graph = ((f"{ros2[0]}/{ros2[1].strip('/')}/**",), (f"@ros2_lv/{ros2[0]}/**",)) if ros2 else ((), ())
    if ros2:
        for v in vehicles:
            k = keys.Keys(v)
            out[node_user("ros2", v)] = Grant(publish=ros_topics + (k.health("ros2"),), announce=graph,
                                              subscribe=(k.pose, k.decision, k.cloud, k.layers),
                                              query=(k.service("octree"),))
    allowed = OPERATOR_QUERIES + (("save",) if operator_can_save else ())
    out[OPERATOR] = Grant(subscribe=(f"{keys.PREFIX}/**",) + ros_topics,  # every topic and every node's health
                          query=tuple(f"{keys.PREFIX}/*/map/{name}" for name in allowed)
                          + (f"{keys.PREFIX}/*/decide/aggregates",), announce=graph, watch=graph)
    return out


def access_control(table: dict[str, Grant]) -> dict:
    """Zenoh's ``access_control`` table for ``grants``: one subject per user name, allow rules, deny the rest.

    Seen from the hub, a user's own messages arrive on its session (``ingress``) and what it is
    delivered leaves on it (``egress``): publishing is an ingress put, receiving an egress put.
    """
    rules, subjects, policies = [], [], []
    for user, g in table.items():
        ids: list[str] = []
        for what, messages, flow, key_exprs in (
                ("publish", ["put"], "ingress", g.publish),
                ("listeners", ["declare_subscriber"], "egress", g.publish),  # who listens: a photo folder waits
                ("subscribe", ["declare_subscriber"], "ingress", g.subscribe),
                ("receive", ["put"], "egress", g.subscribe),
                ("query", ["query"], "ingress", g.query),
                ("replies", ["reply"], "egress", g.query),
                ("answer", ["declare_queryable", "reply"], "ingress", g.answer),
                ("queries", ["query"], "egress", g.answer),
                ("announce", ["liveliness_token"], "ingress", g.announce),
                ("watch", ["declare_liveliness_subscriber", "liveliness_query"], "ingress", g.watch),
                ("graph", ["liveliness_token", "reply"], "egress", g.watch)):
            if key_exprs:
                ids.append(f"{user}/{what}")
                rules.append({"id": ids[-1], "permission": "allow", "flows": [flow], "messages": messages,
                              "key_exprs": list(key_exprs)})
        subjects.append({"id": user, "usernames": [user]})
        policies.append({"id": user, "rules": ids, "subjects": [user]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


class JoinRefused(ValueError):
    """A session could not join the mission's hub: not running, wrong password, or no client certificate."""


# --- credentials ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Credentials:
    """One user's login: the value of Zenoh's ``transport/auth/usrpwd`` table."""

    user: str
    password: str

    def usrpwd(self) -> dict[str, str]:
        return {"user": self.user, "password": self.password}


def _private(path: Path, what: str) -> None:
    """Refuse a secret that others on this machine may read (like ssh does)."""
    mode = stat.S_IMODE(path.stat().st_mode)
    if mode & 0o077:
        raise ConfigError(f"{what} {path} is open to other users (mode {mode:04o}); chmod "
                          f"{'700' if path.is_dir() else '600'} it")


def load_credentials(path: str | Path) -> Credentials:
    """A node's ``--credentials`` file; errors name the file."""
    path = Path(path)
    try:
        _private(path, "--credentials")
        data = json.loads(path.read_text())
        creds = Credentials(str(data["user"]), str(data["password"]))
    except FileNotFoundError:
        raise ConfigError(f"--credentials {path}: no such file (`layerpilot up` writes them into its --secrets "
                          f"directory)") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"--credentials {path}: not a credentials file ({exc})") from None
    if not creds.user or not creds.password or ":" in creds.user:
        raise ConfigError(f"--credentials {path}: needs a user (no ':') and a password")
    return creds


def _write_private(path: Path, text: str) -> None:
    """Write ``text`` atomically into a file that only this user can read."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(tmp, 0o600)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@dataclass(frozen=True)
class MissionSecrets:
    """The secrets directory of one mission (see the module docstring)."""

    directory: Path

    def credentials_file(self, user: str) -> Path:
        return self.directory / f"{user}.json"

    @property
    def dictionary(self) -> Path:
        return self.directory / "users.txt"

    @property
    def acl_file(self) -> Path:
        return self.directory / "access_control.json"


def prepare_secrets(directory: str | Path, table: dict[str, Grant]) -> MissionSecrets:
    """Create (or reuse) every user's credentials, write the hub's dictionary and the allow-list."""
    d = Path(directory)
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    _private(d, "bus secrets directory")
    s = MissionSecrets(d)
    lines = []
    for user in table:
        f = s.credentials_file(user)
        try:
            creds = load_credentials(f)
            if creds.user != user:
                raise ConfigError(f"{f} is for user {creds.user!r}")
        except ConfigError:
            if f.exists():
                _log.warning("%s unusable: writing a new password for %s", f, user)
            creds = Credentials(user, _random.token_urlsafe(24))
            _write_private(f, json.dumps(creds.usrpwd(), indent=1) + "\n")
        lines.append(f"{creds.user}:{creds.password}\n")
    _write_private(s.dictionary, "".join(lines))
    _write_private(s.acl_file, json.dumps(access_control(table), indent=1) + "\n")
    return s


# --- sessions -------------------------------------------------------------------------------------


def client_endpoint(endpoint: str) -> str:
    """Where a node on the hub's machine connects: a listen-on-all address becomes loopback
    (``tls/0.0.0.0:7447`` -> ``tls/localhost:7447``, the name the hub's certificate carries)."""
    proto, _, address = endpoint.partition("/")
    host, sep, port = address.rpartition(":")
    if host in ("0.0.0.0", "[::]"):
        host = "localhost" if proto in ("tls", "quic") else ("127.0.0.1" if host == "0.0.0.0" else "[::1]")
    return f"{proto}/{host}{sep}{port}"


def hub_config(cfg: BusConfig, secrets: MissionSecrets, acl: dict) -> zenoh.Config:
    """The hub: a router on the mission's endpoints that checks logins and enforces ``acl``."""
    z = zenoh_config(dataclasses.replace(cfg, mode="router"), listen=[cfg.endpoint, *cfg.listen],
                     connect=list(cfg.connect))
    z.insert_json5("scouting/gossip/enabled", "false")  # clients do not gossip; the hub tells no one about anyone
    z.insert_json5("transport/auth/usrpwd", json.dumps({"dictionary_file": str(secrets.dictionary.resolve())}))
    z.insert_json5("access_control", json.dumps(acl))
    return z


def open_hub(cfg: BusConfig, secrets_dir: str | Path, vehicles: list[str],
             operator_can_save: bool | None = None, photos: bool = False,
             ros2: tuple[int, str] | None = None) -> tuple[zenoh.Session, MissionSecrets]:
    """Prepare the mission's secrets and open its hub session (the endpoints as ``check_security`` allows)."""
    cfg.check_security()
    table = grants(vehicles, cfg.operator_can_save if operator_can_save is None else operator_can_save, photos, ros2)
    s = prepare_secrets(secrets_dir, table)
    try:
        return zenoh.open(hub_config(cfg, s, access_control(table))), s
    except zenoh.ZError as exc:
        raise JoinRefused(f"bus: cannot open the mission's hub on {cfg.endpoint}: {exc}") from None


def node_config(cfg: BusConfig, creds: Credentials) -> zenoh.Config:
    """A node (or the operator) logging in to the hub as a client: no listening socket of its own."""
    z = zenoh_config(dataclasses.replace(cfg, mode="client"), listen=[],
                     connect=[client_endpoint(cfg.endpoint), *cfg.connect])
    z.insert_json5("transport/auth/usrpwd", json.dumps(creds.usrpwd()))
    return z


def open_node_session(cfg: BusConfig, credentials: str | Path | None) -> zenoh.Session:
    """A node's session: with credentials, a client of the mission's hub; without, the plain peer
    (which a hub with ``bus.security`` on refuses: for tests and debugging on an open bus)."""
    if credentials is None:
        if cfg.security:
            _log.warning("no --credentials: joining as an unauthenticated peer; a mission hub with "
                         "bus.security on refuses this node")
        return open_session(cfg)
    creds = load_credentials(credentials)
    try:
        return zenoh.open(node_config(cfg, creds))
    except zenoh.ZError as exc:
        raise JoinRefused(f"bus: user {creds.user!r} could not join the hub at {client_endpoint(cfg.endpoint)} "
                          f"(not running, wrong password, or no client certificate): {exc}") from None
