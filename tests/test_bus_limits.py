"""A reader's own cap on a layer set's cells is checked before a layer is decoded: a valid 2048x2048 set
(a few hundred KB on the wire) costs the decide node nothing when its mission's window is 256x256."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from layerpilot.bus.layerset import GridLayersMessage, decode_layer_set, encode_layer_set, to_column_layers
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage
from layerpilot.grid import GridGeometry


def column_set(n: int) -> bytes:
    return encode_layer_set(GridLayersMessage(9.0, "uav1", GridGeometry(-n / 2, -n / 2, 1.0, n, n), {
        "observed": np.ones((n, n), bool), "elevation": np.zeros((n, n), np.float32),
        "color": np.zeros((n, n, 3), np.uint8), "last_seen": np.zeros((n, n)),
        "min_distance": np.ones((n, n), np.float32)}), max_bytes=64 << 20)


def peak_mb(fn) -> float:
    """The most memory (numpy's buffers included) ``fn`` held at once, in MB."""
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1] / 1e6
    finally:
        tracemalloc.stop()


def test_a_set_over_the_readers_cap_is_refused_before_decoding():
    big = column_set(2048)
    assert len(big) < 1_000_000  # cheap to send
    with pytest.raises(BadMessage, match="2048x2048 cells is more than 65536"):
        decode_layer_set(big, max_cells=256 * 256)
    refused = peak_mb(lambda: pytest.raises(BadMessage, decode_layer_set, big, max_cells=256 * 256))
    decoded = peak_mb(lambda: to_column_layers(decode_layer_set(big)))  # what the cap saves
    assert refused < 2 * len(big) / 1e6 + 1, refused  # the payload's parse, nothing more
    assert decoded > 80, decoded
    small = decode_layer_set(column_set(256), max_cells=256 * 256)
    assert small.geometry.shape == (256, 256)


def test_a_readers_cap_never_exceeds_the_bus_limit():
    m = pb.LayerSet()
    m.ParseFromString(column_set(16))
    m.grid.width = m.grid.height = 4096
    with pytest.raises(BadMessage, match="4096x4096 cells is more than 4194304"):
        decode_layer_set(m.SerializeToString(), max_cells=1 << 40)
