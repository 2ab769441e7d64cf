"""The depth node: camera frames in, map-frame point clouds out (stereo, or the frame's own depth)."""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Literal

import numpy as np
import zenoh

from layerpilot.bus import keys
from layerpilot.bus.guard import guarded
from layerpilot.bus.messages import Cloud, Frame, decode_frame, encode_cloud, matrix_from_quat
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.bus.session import publish
from layerpilot.config import check_range
from layerpilot.depth.frames import Frame as DepthFrame
from layerpilot.nodes.queue import DropOldest

_log = logging.getLogger("layerpilot.depth")


@dataclass(frozen=True)
class DepthNodeConfig:
    """The ``[depth]`` table of a mission file."""

    source: Literal["stereo", "ground_truth"] = "stereo"
    max_depth: float = 100.0  # m: ground-truth pixels beyond are dropped; the map's max range for the clouds
    stride: int = 2  # ground truth: every stride-th pixel in each direction
    queue_size: int = 4

    def __post_init__(self) -> None:
        check_range("depth.max_depth", self.max_depth, 1.0)
        check_range("depth.stride", self.stride, 1, 64)
        check_range("depth.queue_size", self.queue_size, 1, 1000)


def to_depth_frame(f: Frame) -> DepthFrame:
    pose = np.eye(4)
    pose[:3, :3] = matrix_from_quat(f.orientation)
    pose[:3, 3] = f.position
    fx, fy, cx, cy = f.intrinsics
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    return DepthFrame(f.image, pose, K, f.stamp, f.depth)


class DepthNode:
    def __init__(self, session: zenoh.Session, vehicle: str, cfg: DepthNodeConfig) -> None:
        from layerpilot.depth.config import preset_for
        from layerpilot.depth.source import GroundTruthDepth, StereoDepth

        self.session, self.keys, self.cfg = session, keys.Keys(vehicle), cfg
        self.rejects = Rejects(_log)
        self.queue: DropOldest[Frame] = DropOldest(cfg.queue_size)
        self._stereo_factory = lambda width: StereoDepth(preset_for(width))
        self.source = GroundTruthDepth(cfg.max_depth, cfg.stride) if cfg.source == "ground_truth" else None
        self.clouds = 0
        self._thread = threading.Thread(target=self._loop, name="depth", daemon=True)
        self._sub = None

    def start(self) -> None:
        self._sub = self.session.declare_subscriber(self.keys.camera,
                                                    guarded(decode_frame, lambda f, k: self.queue.put(f), self.rejects))
        self._thread.start()

    def stop(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
        self.queue.close()
        self._thread.join()

    def _loop(self) -> None:
        while (frame := self.queue.get()) is not None:
            try:
                depth_frame = to_depth_frame(frame)
            except ValueError as exc:
                self.rejects.reject(self.keys.camera, BadMessage("bad frame", str(exc)))
                continue
            if self.source is None:  # stereo presets depend on the image size: choose on the first frame
                self.source = self._stereo_factory(depth_frame.size[0])
            cloud = self.source.push(depth_frame)
            if cloud is None or len(cloud) == 0:
                continue
            self.clouds += 1
            publish(self.session, self.keys.cloud, encode_cloud(Cloud(
                cloud.stamp, self.keys.vehicle, frame.seq, cloud.points, cloud.origin, cloud.colors,
                self.cfg.max_depth)))
