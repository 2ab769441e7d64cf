"""The simulated autopilot's MAVLink connection: its transports, one encoder out, a parser per peer in."""

from __future__ import annotations

from collections.abc import Iterator, Sequence

from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.sim.vehicle_transport import TcpServer, UdpEndpoint, open_transport


class EndpointPort:
    """Serves the URLs; what the encoder writes goes to every peer of every transport unless paused."""

    def __init__(self, urls: Sequence[str], system_id: int, component_id: int) -> None:
        if not urls:
            raise ValueError("urls: give at least one tcp:/udpin:/udpout: URL")
        self._transports: list[TcpServer | UdpEndpoint] = []
        try:
            for url in urls:
                self._transports.append(open_transport(url))
        except OSError as exc:
            self.close()
            raise OSError(f"urls: cannot serve {url}: {exc}") from None
        self.mav = mav.MAVLink(self, system_id, component_id)
        self._parsers: dict[tuple, mav.MAVLink] = {}
        self.paused = False
        self.messages_received = 0

    def write(self, data: bytes) -> None:
        """The encoder's file-like target."""
        if not self.paused:
            for transport in self._transports:
                transport.send(data)

    @property
    def addresses(self) -> list[tuple[str, int]]:
        return [t.address for t in self._transports]

    @property
    def clients(self) -> int:
        return sum(t.peers for t in self._transports)

    def receive(self) -> Iterator[mav.MAVLink_message]:
        """Every whole message that arrived since the last call, from any peer."""
        for transport in self._transports:
            for peer, data in list(transport.poll()):
                parser = self._parsers.get(peer)
                if parser is None:
                    parser = self._parsers[peer] = mav.MAVLink(None)
                    parser.robust_parsing = True
                for msg in parser.parse_buffer(data) or []:
                    if msg.get_type() != "BAD_DATA":
                        self.messages_received += 1
                        yield msg

    def close(self) -> None:
        for transport in self._transports:
            transport.close()
        self._transports = []
