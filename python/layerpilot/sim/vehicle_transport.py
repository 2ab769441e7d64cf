"""Byte transports of the simulated vehicle's MAVLink endpoint: a TCP server and UDP sockets.

Non-blocking and polled from the endpoint's step, so the endpoint runs in
lock-step with a mission clock as well as in a real-time loop. Every transport
broadcasts what the vehicle sends to all of its peers (like ArduPilot's SITL
serving several ground stations on one port).
"""

from __future__ import annotations

import select
import socket
from collections.abc import Iterator

RECV_BYTES = 65536  # per read of a peer


def parse_url(url: str) -> tuple[str, str, int]:
    """``tcp:HOST:PORT`` / ``udpin:HOST:PORT`` / ``udpout:HOST:PORT`` -> (kind, host, port)."""
    kind, _, rest = url.partition(":")
    host, _, port = rest.rpartition(":")
    if kind not in ("tcp", "udpin", "udpout", "udp") or not host or not port.isdigit():
        raise ValueError(f"url: expected tcp:HOST:PORT, udpin:HOST:PORT or udpout:HOST:PORT, got {url!r}")
    return ("udpin" if kind == "udp" else kind), host, int(port)


class TcpServer:
    """Listens on HOST:PORT and serves any number of clients at once."""

    def __init__(self, host: str, port: int) -> None:
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind((host, port))
        self._listener.listen(8)
        self._listener.setblocking(False)
        self._clients: dict[tuple, socket.socket] = {}

    @property
    def address(self) -> tuple[str, int]:
        return self._listener.getsockname()[:2]

    @property
    def peers(self) -> int:
        return len(self._clients)

    def poll(self) -> Iterator[tuple[tuple, bytes]]:
        """Accept new clients; yield (peer, bytes) for everything received. One ``select`` finds
        what is ready: the endpoint polls every step, and in a busy process each call that lets go of
        the GIL costs far more than the system call itself."""
        sockets = {conn: peer for peer, conn in self._clients.items()}
        ready, _, _ = select.select([self._listener, *sockets], [], [], 0)
        for sock in ready:
            if sock is self._listener:
                self._accept()
                continue
            peer = sockets[sock]
            while True:
                try:
                    data = sock.recv(RECV_BYTES)
                except BlockingIOError:
                    break
                except OSError:
                    data = b""
                if not data:
                    self._drop(peer)
                    break
                yield peer, data
                if len(data) < RECV_BYTES:  # drained (what arrives meanwhile waits for the next poll)
                    break

    def _accept(self) -> None:
        while True:
            try:
                conn, addr = self._listener.accept()
            except (BlockingIOError, OSError):
                return
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._clients[("tcp",) + addr] = conn

    def send(self, data: bytes) -> None:
        for peer, conn in list(self._clients.items()):
            try:
                conn.send(data)
            except BlockingIOError:
                pass  # a client that does not read loses data, like a radio link
            except OSError:
                self._drop(peer)

    def _drop(self, peer: tuple) -> None:
        conn = self._clients.pop(peer, None)
        if conn is not None:
            conn.close()

    def close(self) -> None:
        for peer in list(self._clients):
            self._drop(peer)
        self._listener.close()


class UdpEndpoint:
    """``udpin``: bind and answer whoever sends; ``udpout``: send to a fixed peer (PX4 SITL style)."""

    def __init__(self, kind: str, host: str, port: int) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._peers: set[tuple[str, int]] = set()
        if kind == "udpin":
            self._sock.bind((host, port))
        else:
            self._sock.bind(("0.0.0.0", 0))
            self._peers.add((host, port))
        self._sock.setblocking(False)

    @property
    def address(self) -> tuple[str, int]:
        return self._sock.getsockname()[:2]

    @property
    def peers(self) -> int:
        return len(self._peers)

    def poll(self) -> Iterator[tuple[tuple, bytes]]:
        while True:
            try:
                data, addr = self._sock.recvfrom(65536)
            except (BlockingIOError, ConnectionRefusedError):
                break
            except OSError:
                break
            self._peers.add(addr[:2])
            yield ("udp",) + addr[:2], data

    def send(self, data: bytes) -> None:
        for peer in list(self._peers):
            try:
                self._sock.sendto(data, peer)
            except (BlockingIOError, ConnectionRefusedError):
                pass
            except OSError:
                pass

    def close(self) -> None:
        self._sock.close()


def open_transport(url: str) -> TcpServer | UdpEndpoint:
    kind, host, port = parse_url(url)
    return TcpServer(host, port) if kind == "tcp" else UdpEndpoint(kind, host, port)
