"""Layer sets on the bus: LZ4 by default, zlib when only that fits, hostile LZ4 refused, one encoding per map change."""

from __future__ import annotations

import lz4.block
import numpy as np
import pytest

from layerpilot.bus import arrays
from layerpilot.bus.layerset import GridLayersMessage, decode_layer_set, encode_layer_set, to_column_layers
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.grid import GridGeometry
from layerpilot.missionfile import Mission
from layerpilot.mission.map_service import MapServiceConfig
from layerpilot.nodes.map_server import MapServer
from test_nodes_map_server import ground_cloud

G = GridGeometry(0.0, 0.0, 1.0, 256, 128)


def test_layer_sets_travel_lz4_and_fall_back_to_zlib_to_fit() -> None:
    rng = np.random.default_rng(0)
    small_alphabet = rng.integers(0, 2, G.shape, dtype=np.uint8)  # LZ4 finds no repeats; zlib's Huffman codes do
    message = GridLayersMessage(1.0, "uav1", G, {"a": small_alphabet, "b": np.linspace(0, 1, G.width * G.height,
                                                                                         dtype=np.float32).reshape(G.shape)})
    fast = encode_layer_set(message)
    assert {lm.data.compression for lm in pb.LayerSet.FromString(fast).layers} == {pb.Array.LZ4}
    lz4_size = len(fast)
    tight = encode_layer_set(message, max_bytes=lz4_size - 1)
    assert len(tight) < lz4_size and pb.LayerSet.FromString(tight).layers[0].data.compression == pb.Array.ZLIB
    for payload in (fast, tight):
        back = decode_layer_set(payload)
        np.testing.assert_array_equal(back.layers["a"], small_alphabet)
        np.testing.assert_array_equal(back.layers["b"], message.layers["b"])
    with pytest.raises(ValueError, match="more than max_bytes=1000"):
        encode_layer_set(message, max_bytes=1000)


def test_hostile_lz4_is_refused_with_the_reason() -> None:
    good = arrays.to_proto(np.arange(1000, dtype=np.float32), compress="lz4")
    assert (arrays.from_proto(good, "x") == np.arange(1000)).all()
    garbage = pb.Array(dtype="float32", shape=[1000], data=b"\xff" * 64, compression=pb.Array.LZ4)
    with pytest.raises(BadMessage, match="lz4"):
        arrays.from_proto(garbage, "x")
    short = pb.Array(dtype="float32", shape=[2000], data=good.data, compression=pb.Array.LZ4)
    with pytest.raises(BadMessage, match="needs 8000 bytes, got 4000"):
        arrays.from_proto(short, "x")
    # a bomb: 8 MB of zeros in 32 kB, declared as 100 floats, never inflates past 400 bytes
    bomb = lz4.block.compress(bytes(8 << 20), store_size=False)
    with pytest.raises(BadMessage, match="lz4"):
        arrays.from_proto(pb.Array(dtype="float32", shape=[100], data=bomb, compression=pb.Array.LZ4), "x")
    huge = pb.Array(dtype="float32", shape=[1 << 30], data=bomb, compression=pb.Array.LZ4)
    with pytest.raises(BadMessage, match="too large"):
        arrays.from_proto(huge, "x")
    # within the item limit (2^28) but 2 GiB of float64: past what an LZ4 block can hold (was an OverflowError)
    at_limit = pb.Array(dtype="float64", shape=[1 << 28], data=bomb, compression=pb.Array.LZ4)
    with pytest.raises(BadMessage, match="x: .*more than an LZ4 block holds"):
        arrays.from_proto(at_limit, "x")


def test_map_server_encodes_a_window_once_per_map_change() -> None:
    session = open_session(BusConfig(endpoint=free_endpoint()))
    try:
        server = MapServer(session, Mission(map_server=MapServiceConfig(resolution=0.5, snapshot="",
                                                                        window=(-10.0, -10.0, 40, 40))))
        first = server.layer_set("uav1")
        assert server.layer_set("uav1") is first  # nothing changed: the same bytes
        assert not to_column_layers(decode_layer_set(first)).observed.any()
        other = server.layer_set("uav1", -5.0, -5.0, 20, 20)
        assert other is not first and server.layer_set("uav1", -5.0, -5.0, 20, 20) is other
        c = ground_cloud(1.0).cloud
        server.service.insert(c.points, c.origin, c.colors, c.stamp)
        after = server.layer_set("uav1")
        assert after is not first and to_column_layers(decode_layer_set(after)).observed.sum() > 1000
        assert server.layer_set("uav1") is after
    finally:
        session.close()
