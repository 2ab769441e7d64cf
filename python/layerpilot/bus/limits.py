"""Size limits per message type, checked before anything is decompressed or allocated.

A small payload must not become a large allocation: every array's declared shape is
checked against its message type's limit before its bytes are inflated, and zlib is
asked for at most the declared size. The limits are documented in docs/bus.md's key table.
"""

from __future__ import annotations

MAX_CLOUD_POINTS = 1 << 20  # points per cloud: a 1024x1024 depth image
MAX_FRAME_PIXELS = 4096 * 3072  # pixels per camera frame: a 12.6 MP drone photo
MAX_LAYER_CELLS = 2048 * 2048  # cells per layer set: the map server's largest window
MAX_LAYERS = 16  # layers per layer set
MIN_RESOLUTION, MAX_RESOLUTION = 1e-3, 1e3  # m per grid cell of a layer set
MAX_COORDINATE = 1e7  # m: positions and grid origins beyond are refused (the map frame is local)
MAX_PAYLOAD_BYTES = 64 << 20  # any one message on the wire
