"""`layerpilot bench bus`: the map server's layer-query round trip and cloud throughput on loopback.

The reference for the query is a bare Zenoh queryable answering a payload of the same size
from memory: the ratio says what the map (column extraction + encoding) adds to transport.
A query for a window the map server has encoded since the last insertion is answered from
its cache; "fresh" queries ask for a window shifted by one more cell each time, so each is
extracted and encoded anew (a window never asked for); "after insert" queries follow one
more cloud each, for the same window (the usual case: the first extraction after an insert
also pays for the map's own bookkeeping of that insert).
The breakdown times each step of a query in process (median of the same number of runs):
the map's column extraction (C++), the layer-set encoding, and the pilot's decoding (not
part of the round trip, but paid by every reader).
"""

from __future__ import annotations

import json
import os
import platform
import time

import numpy as np

from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.layerset import decode_layer_set, encode_columns, to_column_layers
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.geometry import PointCloud
from layerpilot.missionfile import Mission
from layerpilot.mission.map_service import MapServiceConfig
from layerpilot.nodes.map_server import MapServer

K = Keys("bench")


def survey_cloud(i: int, width: int, height: int, speed: float, rate: float, rng: np.random.Generator) -> msg.CloudMessage:
    """One depth frame's cloud: a 60-degree camera pitched 60 degrees down from 30 m over 0-8 m tall clutter."""
    origin = np.array([i * speed / rate, 0.0, 30.0])
    f = 0.5 * width / np.tan(np.radians(30))
    u, v = np.meshgrid(np.arange(width) - width / 2 + 0.5, np.arange(height) - height / 2 + 0.5)
    pitch = np.radians(60)
    # camera x = right (-y world), y = down, z = forward tilted below the +x axis
    fwd = np.array([np.cos(pitch), 0, -np.sin(pitch)])
    down = np.array([-np.sin(pitch), 0, -np.cos(pitch)])
    right = np.array([0, -1.0, 0])
    d = (u.ravel()[:, None] * right + v.ravel()[:, None] * down + f * fwd) / f
    ground = rng.uniform(0, 8, len(d))
    t = (origin[2] - ground) / -d[:, 2]
    pts = (origin + d * t[:, None]).astype(np.float32)
    return msg.CloudMessage(K.vehicle, i, PointCloud(pts, origin, i / rate))


def run(seconds: float = 5.0, rate: float = 10.0, width: int = 320, height: int = 240, queries: int = 30,
        window: int = 512, resolution: float = 0.5) -> dict:
    ep = free_endpoint()
    server_session, client = open_session(BusConfig(endpoint=ep)), open_session(BusConfig(endpoint=ep))
    mission = Mission(vehicles=[K.vehicle], map_server=MapServiceConfig(resolution=resolution, snapshot="",
                                                                        layers_rate=0.01))
    server = MapServer(server_session, mission)
    server.start()
    rng = np.random.default_rng(0)
    try:
        time.sleep(0.5)
        clouds = [msg.encode_cloud(survey_cloud(i, width, height, 5.0, rate, rng)) for i in range(int(seconds * rate))]
        start = time.perf_counter()
        for i, c in enumerate(clouds):  # paced like a camera
            time.sleep(max(0.0, start + i / rate - time.perf_counter()))
            client.put(K.cloud, c)
        while server.service.clouds_inserted + server.queue.dropped + server.rejects.total < len(clouds):
            time.sleep(0.005)
        elapsed = time.perf_counter() - start
        inserted, dropped = server.service.clouds_inserted, server.queue.dropped

        half = window * resolution / 2
        selector = f"{K.service('layers')}?x={-half};y={-half};w={window};h={window}"
        rtt, size = _round_trips(client, selector, queries)
        shifted = [f"{K.service('layers')}?x={-half + i * resolution};y={-half};w={window};h={window}"
                   for i in range(1, queries + 1)]  # a window not asked for yet: extracted and encoded anew
        fresh = [_round_trips(client, s, 1)[0][0] for s in shifted]
        after_insert = []
        for i in range(queries):  # one more cloud lands, then the same window is asked for
            done = server.service.clouds_inserted
            client.put(K.cloud, msg.encode_cloud(survey_cloud(len(clouds) + i, width, height, 5.0, rate, rng)))
            while server.service.clouds_inserted == done:
                time.sleep(0.002)
            after_insert.append(_round_trips(client, selector, 1)[0][0])
        payload = bytes(size)
        ref = server_session.declare_queryable("bench/reference", lambda q: (q.reply(q.key_expr, payload), q.drop()))
        time.sleep(0.3)
        ref_rtt, _ = _round_trips(client, "bench/reference", queries)
        ref.undeclare()
        steps = _breakdown(server, window, resolution, queries)
    finally:
        server.stop()
        client.close()
        server_session.close()
    return {
        "bench": "bus", "cloud_size": f"{width}x{height}", "points_per_cloud": width * height,
        "clouds_offered_per_s": rate, "clouds_sent": len(clouds), "clouds_inserted": inserted,
        "clouds_dropped": dropped, "clouds_inserted_per_s": round(inserted / elapsed, 2),
        "keeps_up": dropped == 0,
        "layer_window": f"{window}x{window}", "layer_set_bytes": size,
        "layer_query_ms_median": round(1e3 * float(np.median(rtt)), 2),
        "layer_query_ms_p95": round(1e3 * float(np.percentile(rtt, 95)), 2),
        "layer_query_fresh_ms_median": round(1e3 * float(np.median(fresh)), 2),
        "layer_query_after_insert_ms_median": round(1e3 * float(np.median(after_insert)), 2),
        "reference_same_bytes_ms_median": round(1e3 * float(np.median(ref_rtt)), 2),
        "ratio_vs_reference": round(float(np.median(rtt) / np.median(ref_rtt)), 2),
        "fresh_ratio_vs_reference": round(float(np.median(fresh) / np.median(ref_rtt)), 2),
        **steps,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}",
    }


def _breakdown(server: MapServer, window: int, resolution: float, n: int) -> dict[str, float]:
    """Median ms of each step of a layer query, in process."""
    half = window * resolution / 2
    columns = server.service.columns(-half, -half, window, window)
    payload = encode_columns(columns, 0.0, K.vehicle)
    steps = {"columns": lambda: server.service.columns(-half, -half, window, window),
             "encode": lambda: encode_columns(columns, 0.0, K.vehicle),
             "decode": lambda: to_column_layers(decode_layer_set(payload))}
    out = {}
    for name, fn in steps.items():
        times = []
        for _ in range(n):
            t = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t)
        out[f"{name}_ms_median"] = round(1e3 * float(np.median(times)), 2)
    return out


def _round_trips(session, selector: str, n: int) -> tuple[list[float], int]:
    times, size = [], 0
    for _ in range(n):
        t = time.perf_counter()
        replies = list(session.get(selector, timeout=10.0))
        times.append(time.perf_counter() - t)
        if not replies or replies[0].ok is None:
            raise RuntimeError(f"no answer to {selector}")
        size = len(replies[0].ok.payload.to_bytes())
    return times, size


def main(seconds: float, rate: float) -> int:
    result = run(seconds=seconds, rate=rate)
    for k, v in result.items():
        print(f"{k:>32}: {v}")
    print(json.dumps(result))
    return 0
