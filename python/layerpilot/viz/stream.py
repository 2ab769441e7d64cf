"""Where a mission's Rerun recording goes: an .rrd file, the web viewer on localhost, the native viewer.

The web viewer is two local servers: Rerun's gRPC server holding the recording (``grpc_port``) and
the static viewer page (``web_port``), which connects to it; ``url`` is what a browser opens.
"""

from __future__ import annotations

import os
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
        server = rr.GrpcServerSink(bind_ip="127.0.0.1", port=grpc_port)
        sinks.append(server)
        rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=server.uri)
        url = f"http://127.0.0.1:{web_port}/?url={quote(server.uri, safe='')}"
    if spawn:  # the native viewer, listening on grpc_port
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise ValueError("the native viewer needs a display (DISPLAY and WAYLAND_DISPLAY are unset): "
                             "use the web viewer (view --web, demo --view web)")
        rr.spawn(port=grpc_port, connect=False)
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{grpc_port}/proxy"))
    stream.set_sinks(*sinks, default_blueprint=layout())
    return ViewStream(stream, url)


def layout():
    """The viewer's first layout: the 3D scene large; layers, camera, decisions and time series beside it."""
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
                         rrb.TextLogView(origin="decision", name="decisions"),
                         rrb.Tabs(rrb.TimeSeriesView(origin="metrics", name="metrics"), *nodes,
                                  rrb.TimeSeriesView(origin="health", contents=["health/rate/**", "health/map/**",
                                                                                "health/view/**"], name="bus"))),
            column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed"))
