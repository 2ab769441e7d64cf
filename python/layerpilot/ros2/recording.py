"""ROS 2 channels for mission recordings: each bus message's ROS 2 translation, as ``ros2 bag`` writes MCAP.

A channel per ROS 2 topic (``/layerpilot/uav1/pose``), message encoding ``cdr``, its schema the type's
concatenated ``.msg`` definition with encoding ``ros2msg``, named ``geometry_msgs/msg/PoseStamped``.
"""

from __future__ import annotations

from typing import Any

from layerpilot.bus.recording import ExtraMessage, Translate
from layerpilot.ros2.messages import serialize
from layerpilot.ros2.topics import Ros2Config, Ros2Topics


def ros2_channels(cfg: Ros2Config) -> Translate:
    """The recorder's ``translate``: the ROS 2 messages of one bus message (none for camera, health, ...)."""
    topics = Ros2Topics(cfg)

    def translate(bus_topic: str, payload: bytes) -> list[ExtraMessage]:
        return [ExtraMessage(m.topic, m.type.name, "ros2msg", m.type.definition, "cdr",
                             serialize(m.message, m.type.name))
                for m in topics.translate(bus_topic, payload)]

    return translate


MODES = ("off", "beside", "only")  # ROS 2 channels: none, beside the protobuf ones, instead of them


def recording_options(mode: str, cfg: Ros2Config) -> dict[str, Any]:
    """The Recorder's ``translate`` and ``protobuf`` arguments for ``--ros2 MODE``."""
    if mode not in MODES:
        raise ValueError(f"--ros2: expected one of {', '.join(MODES)}, got {mode!r}")
    return {} if mode == "off" else {"translate": ros2_channels(cfg), "protobuf": mode == "beside"}
