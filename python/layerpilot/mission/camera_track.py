"""A real camera's frame poses: the vehicle's pose stream interpolated at the frame's time, then the mount.

The link node publishes the vehicle's pose (body FLU -> map) at ``link.pose_rate`` on the
mission clock; a camera frame taken between two poses gets the pose between them (position
linear, rotation slerp). A frame in a telemetry gap longer than ``camera.max_gap``, before the
first pose or after the newest one cannot be placed: it is dropped, and the reason counted.
The camera sits on the body at ``camera.offset`` (m, FLU), looking ``yaw_deg`` left of forward
and ``pitch_deg`` below the horizon, as the simulator's camera does (layerpilot.camera.camera_pose);
on a gimbal (``camera.gimbal``) it keeps only the body's heading, as the simulator renders.
"""

from __future__ import annotations

import bisect
import math
from collections import Counter, deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from layerpilot.config import ConfigError, check_range
from layerpilot.geometry import Pose
from layerpilot.camera import MOUNT_PITCH_DEG, camera_pose


@dataclass(frozen=True)
class CameraSettings:
    """The ``[camera]`` table: where `layerpilot camera` reads frames from and how the camera sits on the body."""

    source: str = "sim"  # sim (the simulator node renders the frames) or what `layerpilot camera` opens
    calibration: str = ""  # OpenCV YAML calibration file of the real camera (photos.calibration)
    pitch_deg: float = MOUNT_PITCH_DEG  # mount: degrees below the body's horizon (90 = nadir)
    yaw_deg: float = 0.0  # mount: degrees left of the body's forward axis
    offset: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # m, body FLU, camera centre
    gimbal: bool = True  # the camera keeps only the body's heading (a stabilised gimbal); false: hard mounted
    max_gap: float = 0.5  # s: a frame between poses further apart is dropped (a telemetry gap)
    latency: float = 0.0  # s from exposure to the frame reaching the node (device and stream sources)
    file_start: float = 0.0  # mission time (s) of a video file's first frame (a photo folder's first photo)
    play_rate: float = 1.0  # a photo folder plays this many times faster than its photos were taken
    reconnect_max: float = 10.0  # s: the longest wait between reopening a dropped stream or device
    history: float = 30.0  # s of poses kept for interpolation

    def __post_init__(self) -> None:
        if not self.source.strip():
            raise ConfigError("camera.source: give 'sim', a device index, a stream URL or a video file")
        check_range("camera.pitch_deg", self.pitch_deg, -90.0, 90.0)
        check_range("camera.yaw_deg", self.yaw_deg, -180.0, 180.0)
        if len(self.offset) != 3 or not all(math.isfinite(float(v)) for v in self.offset):
            raise ConfigError(f"camera.offset: expected 3 finite metres (forward, left, up), got {self.offset}")
        check_range("camera.max_gap", self.max_gap, 0.01, 10.0)
        check_range("camera.latency", self.latency, 0.0, 5.0)
        check_range("camera.file_start", self.file_start, 0.0, 1e7)
        check_range("camera.play_rate", self.play_rate, 0.01, 1000.0)
        check_range("camera.reconnect_max", self.reconnect_max, 0.1, 20.0)  # under the stall limit
        check_range("camera.history", self.history, 1.0, 3600.0)

    @property
    def plays_photos(self) -> bool:
        """The source is a folder of photos (or a project folder holding ``images/``), played as the camera."""
        return self.source != "sim" and Path(self.source).is_dir()

    @property
    def mount(self) -> Pose:
        """Camera (OpenCV axes) -> body FLU."""
        return camera_pose(np.asarray(self.offset, np.float64), math.radians(self.yaw_deg), self.pitch_deg)


def slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) a share ``s`` in [0, 1] of the shortest arc from ``q0`` to ``q1``."""
    q0, q1 = np.asarray(q0, np.float64), np.asarray(q1, np.float64)
    dot = float(q0 @ q1)
    if dot < 0.0:  # q and -q are one rotation: take the short way
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly equal: linear is exact to rounding and avoids dividing by sin(~0)
        q = q0 + s * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = math.acos(dot)
    return (math.sin((1.0 - s) * theta) * q0 + math.sin(s * theta) * q1) / math.sin(theta)


def interpolate(a: Pose, b: Pose, s: float) -> Pose:
    """The pose a share ``s`` of the way from ``a`` to ``b``: position linear, rotation slerp."""
    return Pose(a.position + s * (b.position - a.position), slerp(a.orientation, b.orientation, s))


class PoseTrack:
    """The newest ``history`` seconds of the vehicle's stamped poses; camera poses at any time between them."""

    def __init__(self, settings: CameraSettings) -> None:
        self.settings, self.mount = settings, settings.mount
        self._stamps: list[float] = []
        self._poses: list[Pose] = []
        self.dropped: Counter[str] = Counter()  # reason -> frames without a pose

    def add(self, stamp: float, pose: Pose) -> None:
        """A pose of the stream (late ones are put in order; a repeated stamp is ignored)."""
        i = bisect.bisect_left(self._stamps, stamp)
        if i < len(self._stamps) and self._stamps[i] == stamp:
            return
        self._stamps.insert(i, stamp)
        self._poses.insert(i, pose)
        cut = bisect.bisect_left(self._stamps, self._stamps[-1] - self.settings.history)
        del self._stamps[:cut], self._poses[:cut]

    @property
    def newest(self) -> float:
        return self._stamps[-1] if self._stamps else -math.inf

    def __len__(self) -> int:
        return len(self._stamps)

    def body_at(self, t: float) -> Pose | None:
        """The body pose at mission time ``t``, or None (the reason counted in ``dropped``)."""
        i = bisect.bisect_left(self._stamps, t)
        if i < len(self._stamps) and self._stamps[i] == t:
            return self._poses[i]
        if i == 0 or i == len(self._stamps):
            self.dropped["before the first pose" if i == 0 else "after the newest pose"] += 1
            return None
        t0, t1 = self._stamps[i - 1], self._stamps[i]
        if t1 - t0 > self.settings.max_gap:
            self.dropped["telemetry gap"] += 1
            return None
        return interpolate(self._poses[i - 1], self._poses[i], (t - t0) / (t1 - t0))

    def camera_at(self, t: float) -> Pose | None:
        """The camera pose (camera -> map) at mission time ``t``: the body's, then the mount; None as body_at."""
        if (body := self.body_at(t)) is None:
            return None
        if self.settings.gimbal:
            body = Pose.from_euler(0.0, 0.0, body.yaw, body.position)
        return body @ self.mount


class ClockOffset:
    """Mission time from a local monotonic clock, learnt from the pose stream.

    A pose stamped ``s`` on the mission clock that arrives at local time ``r`` says offset
    ``>= s - r`` (it took some time to arrive); the largest of the last ``window`` poses is the
    one that came fastest, the best estimate.
    """

    def __init__(self, window: int = 100) -> None:
        self._samples: deque[float] = deque(maxlen=window)

    def heard(self, stamp: float, received: float) -> None:
        self._samples.append(stamp - received)

    def __call__(self, local: float) -> float | None:
        """Mission time of local time ``local``; None before the first pose."""
        return local + max(self._samples) if self._samples else None
