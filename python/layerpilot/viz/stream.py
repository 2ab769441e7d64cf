"""Where a mission's Rerun recording goes: an .rrd file, the web viewer, the native viewer.

The web viewer is two servers: Rerun's gRPC server holding the recording (``grpc_port``, bound to
127.0.0.1 only) and the static viewer page (``web_port``), which connects to it; ``url`` is what a
browser opens. Rerun 0.41's ``serve_web_viewer`` has no bind address: the page (HTML, JS and Wasm,
no mission data) listens on every interface (0.0.0.0); the data stays on this machine. Both ports
are checked before the stream is declared ready: a port another process holds is an error here,
not a viewer silently showing that process's data.
"""

from __future__ import annotations

import errno
import os
import socket
import sys
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

import rerun as rr

from layerpilot.bus.keys import NODES

APPLICATION = "layerpilot"


@dataclass
class ViewStream:
    stream: rr.RecordingStream
    url: str = ""  # the web viewer's address, when served

    def close(self) -> None:
        """Flush everything to the sinks (the .rrd gets its footer)."""
        self.stream.flush()
        self.stream.disconnect()


def open_stream(name: str, *, save: str | Path | None = None, web_port: int | None = None,
                grpc_port: int = 9876, spawn: bool = False) -> ViewStream:
    """A recording stream named ``name`` into the asked sinks (any combination; none is a ValueError)."""
    if save is None and web_port is None and not spawn:
        raise ValueError("open_stream: give save, web_port or spawn")
    stream = rr.RecordingStream(APPLICATION, recording_id=name)
    stream.send_recording_name(name)
    sinks, url = [], ""
    if save is not None:
        Path(save).parent.mkdir(parents=True, exist_ok=True)
        sinks.append(rr.FileSink(str(save)))
    if web_port is not None:
        require_free_port("127.0.0.1", grpc_port, "Rerun's data server (--grpc-port)")
        require_free_port("0.0.0.0", web_port, "the web viewer page (--web-port)")
        server = rr.GrpcServerSink(bind_ip="127.0.0.1", port=grpc_port)
        sinks.append(server)
        try:
            rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=server.uri)
        except RuntimeError as exc:  # taken between the check and here
            raise OSError(f"the web viewer page (--web-port): cannot serve on port {web_port}: {exc}") from None
        url = f"http://127.0.0.1:{web_port}/?url={quote(server.uri, safe='')}"
    if spawn:  # the native viewer, listening on grpc_port
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise ValueError("the native viewer needs a display (DISPLAY and WAYLAND_DISPLAY are unset): "
                             "use the web viewer (view --web, demo --view web)")
        rr.spawn(port=grpc_port, connect=False)
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{grpc_port}/proxy"))
    stream.set_sinks(*sinks, default_blueprint=layout())
    return ViewStream(stream, url)


def require_free_port(host: str, port: int, what: str) -> None:
    """OSError naming ``what`` when ``host:port`` cannot be listened on (another server holds it).

    Rerun's servers report a busy port only in a background thread (gRPC) or as a raw RuntimeError
    (the page); a bind probe here gives the user one line to act on."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as Rerun's listeners: TIME_WAIT is free
        try:
            probe.bind((host, port))
        except OSError as exc:
            why = "already in use by another process" if exc.errno == errno.EADDRINUSE else exc.strerror
            raise OSError(f"{what}: port {port} on {host}: {why}; choose another port") from None


def layout():
    """The viewer's first layout: the 3D scene large; layers, camera, decisions (with the view's own warnings)
    and time series beside it."""
    import rerun.blueprint as rrb

    layers = [rrb.Spatial2DView(origin=f"layers/{name}", name=name)
              for name in ("color", "elevation", "time_since_seen", "distance")]
    # the decision's aggregates over the color layer, where the tick computed them
    aggregates = [rrb.Spatial2DView(origin="layers", contents=["layers/color", f"layers/{name}"], name=name)
                  for name in ("A3", "A2", "A1", "A0")]
    nodes = [rrb.TimeSeriesView(origin=f"health/{node}", name=node) for node in NODES]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="mission"),
            rrb.Vertical(rrb.Tabs(*layers, *aggregates, rrb.Spatial2DView(origin="world/camera", name="camera")),
                         rrb.TextLogView(origin="/", contents=["decision", "log"], name="decisions and view log"),
                         rrb.Tabs(rrb.TimeSeriesView(origin="metrics", name="metrics"), *nodes,
                                  rrb.TimeSeriesView(origin="health", contents=["health/rate/**", "health/map/**",
                                                                                "health/view/**"], name="bus"))),
            column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed"))
