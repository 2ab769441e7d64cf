"""The camera node: a real camera's frames on the bus, each with its pose, as the simulator node publishes them.

It reads a device (``camera.source = "0"``), a stream (``rtsp://...``, ``http://...``) or a
video file with OpenCV's ``VideoCapture``, or plays a folder of geotagged photos
(``photos.player``). A frame is stamped on the mission clock: a file's
frame ``i`` at ``file_start + i / fps``; a live frame at its arrival, moved onto the mission
clock by the offset learnt from the link node's pose stream (mission.camera_track.ClockOffset),
less ``latency``; a photo at ``file_start`` plus its capture time after the first photo's, played at
that pace (``play_rate`` times faster), its EXIF/XMP pose published first as the telemetry (pose)
stream; a folder starts playing once a subscriber (the depth node) listens for its frames, so
that no photo goes out to nobody. A frame waits for a pose at or after its time while the pose
stream keeps coming (one at least every ``max_gap`` seconds; a file's frames wait for the first
pose too), gets the interpolated camera pose (mission.camera_track.PoseTrack) or is dropped with
the reason counted, is undistorted with the calibration and goes out on
``layerpilot/<vehicle>/camera``. A file that ends stops the node (exit
0, saying so); a device or stream that stops giving frames is reopened with a doubling wait up to
``reconnect_max``; a photo folder that has played leaves the node idle (``up`` does not replay it).
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

import cv2
import zenoh

from layerpilot.bus import keys
from layerpilot.bus.guard import guarded
from layerpilot.bus.messages import FrameMessage, State, decode_state, encode_frame, encode_state
from layerpilot.bus.reject import Rejects
from layerpilot.bus.session import publish
from layerpilot.geometry import CameraFrame
from layerpilot.mission.camera_track import CameraSettings, ClockOffset, PoseTrack
from layerpilot.nodes.runner import WAKE_PERIOD
from layerpilot.nodes.supervise import Supervisor
from layerpilot.photos.calibration import Calibration, read_calibration
from layerpilot.photos.player import PhotoPlayer, open_player

_log = logging.getLogger("layerpilot.camera")
POSE_ROUND_TRIP = 2.0  # s: a photo's published pose is back from the bus by then, or the photo is dropped


def source_kind(source: str) -> str:
    """``device`` (an index), ``stream`` (a URL), ``photos`` (a folder) or ``file``."""
    if source.isdigit():
        return "device"
    if "://" in source:
        return "stream"
    return "photos" if CameraSettings(source=source).plays_photos else "file"


class CameraNode:
    """``stop`` ends the capture loop; ``ended`` is set when the loop is over (a file's end, or a stop)."""

    def __init__(self, session: zenoh.Session, vehicle: str, settings: CameraSettings,
                 supervisor: Supervisor | None = None) -> None:
        if settings.source == "sim":
            raise ValueError("camera.source is 'sim': give a device index, a stream URL or a video file "
                             "(--source), or let the simulator node render the frames")
        self.kind = source_kind(settings.source)
        if not settings.calibration and self.kind != "photos":  # photos: EXIF's camera unless one is given
            raise ValueError("camera.calibration: give the camera's OpenCV calibration file (--calibration)")
        self.session, self.keys, self.settings = session, keys.Keys(vehicle), settings
        self.calibration: Calibration | None = read_calibration(settings.calibration) if settings.calibration else None
        self.player: PhotoPlayer | None = None
        if self.kind == "photos":
            if settings.gimbal:
                raise ValueError("camera.gimbal: a photo's attitude is the camera's own; set camera.gimbal = false "
                                 "so that its pose is not levelled")
            self.player = open_player(settings.source, settings.mount, settings.file_start, self.calibration)
            for name, why in self.player.folder.skipped.items():
                _log.warning("camera: photo %s skipped: %s", name, why)
        if self.kind == "file" and not Path(settings.source).is_file():
            raise ValueError(f"camera.source: video file {settings.source} not found")
        self.supervisor = supervisor or Supervisor(_log)
        self.rejects = Rejects(_log)
        self.track = PoseTrack(settings)
        self.offset = ClockOffset()
        self.stop_event = threading.Event()
        self.ended = threading.Event()
        self.read = self.published = self.reconnects = 0
        self._cond = threading.Condition()
        self._pose_heard = 0.0  # local monotonic time of the newest pose
        self._cap: cv2.VideoCapture | None = None
        self._fps = 0.0
        self._played_from = 0.0  # local monotonic time the first photo went out
        self._backoff = 0.5
        self._outage = False
        self._sub = None
        self._frames_out: zenoh.Publisher | None = None  # a photo folder's: who listens for its frames
        self._open()

    # --- poses ----------------------------------------------------------------------------

    def start(self) -> None:
        self._sub = self.session.declare_subscriber(self.keys.pose, guarded(decode_state, self._on_pose,
                                                                            self.rejects, self.supervisor))
        if self.player is not None:
            self._frames_out = self.session.declare_publisher(self.keys.camera)

    def _on_pose(self, s: State, key: str) -> None:
        now = time.monotonic()
        with self._cond:
            self.track.add(s.stamp, s.pose)
            self.offset.heard(s.stamp, now)
            self._pose_heard = now
            self._cond.notify_all()

    # --- the capture loop -----------------------------------------------------------------

    def run(self, stop: threading.Event) -> None:
        """Capture until ``stop`` or the file's end (the loop runs supervised; this thread waits)."""
        self.supervisor.start("camera", self._iteration)
        while not (stop.wait(WAKE_PERIOD) or self.ended.is_set() or self.supervisor.failed.is_set()):
            pass
        self.stop_event.set()
        self.supervisor.join(timeout=self.settings.reconnect_max + 2.0)  # the frame in hand goes out first

    def stop(self) -> None:
        self.stop_event.set()
        self.supervisor.join(timeout=self.settings.reconnect_max + 2.0)
        for declared in (self._sub, self._frames_out):
            if declared is not None:
                declared.undeclare()
        self._sub = self._frames_out = None
        if self._cap is not None:
            self._cap.release()
            self._cap = None

    def _open(self) -> bool:
        src = self.settings.source
        if self.player is not None:
            return True
        cap = cv2.VideoCapture(int(src) if self.kind == "device" else src)
        if not cap.isOpened():
            cap.release()
            if self.kind == "file":
                raise ValueError(f"camera.source: cannot read video file {src} (not a video OpenCV can decode)")
            return False
        self._cap, self._fps = cap, cap.get(cv2.CAP_PROP_FPS)
        if self.kind == "file" and not self._fps > 0:
            raise ValueError(f"camera.source: video file {src} has no frame rate")
        return True

    def _iteration(self) -> bool:
        if self.stop_event.is_set():
            self.ended.set()
            return False
        if self.player is not None:
            return self._play_photo()
        ok, image = self._cap.read() if self._cap is not None else (False, None)
        arrived = time.monotonic()
        if not ok:
            return self._no_frame()
        if self._outage:
            _log.warning("camera %s: frames again", self.settings.source)
            self._outage, self._backoff = False, 0.5
        index, self.read = self.read, self.read + 1
        if self.kind == "file":
            stamp = self.settings.file_start + index / self._fps
        elif (mission_time := self.offset(arrived)) is None:
            self.track.dropped["no pose yet"] += 1
            return True
        else:
            stamp = mission_time - self.settings.latency
        if (pose := self._camera_pose(stamp)) is None:
            return True
        h, w = image.shape[:2]
        calibration = self.calibration.for_size(w, h)
        rgb = cv2.cvtColor(calibration.undistort(image), cv2.COLOR_BGR2RGB)
        self.published += 1
        publish(self.session, self.keys.camera, encode_frame(FrameMessage(
            self.keys.vehicle, self.published, CameraFrame(rgb, pose, calibration.intrinsics, stamp))))
        return True

    def _play_photo(self) -> bool:
        """The next photo when it is due (its pose first, as telemetry; the frame is placed from the pose
        stream as any frame is); idle once the folder has played."""
        player, index = self.player, self.read
        if index == len(player):
            _log.info("camera: photo folder %s played: %d photos (%d published, %d dropped); idle",
                      self.settings.source, index, self.published, self.dropped)
        if index >= len(player):
            self.read = len(player) + 1
            self.stop_event.wait(WAKE_PERIOD)
            return True
        if index == 0:
            self._await_listener()
            self._played_from = time.monotonic()
        due = self._played_from + (player.stamps[index] - player.stamps[0]) / self.settings.play_rate
        while not self.stop_event.is_set() and (wait := due - time.monotonic()) > 0:
            self.supervisor.beat("camera")
            self.stop_event.wait(min(wait, WAKE_PERIOD))
        if self.stop_event.is_set():
            return True
        self.read += 1
        stamp = float(player.stamps[index])
        publish(self.session, self.keys.pose, encode_state(State(stamp, self.keys.vehicle, player.body_pose(index))),
                lossless=True)
        frame = player.frame(index)
        with self._cond:  # the pose comes back through the bus, as any telemetry does
            self._cond.wait_for(lambda: self.track.newest >= stamp or self.stop_event.is_set(), POSE_ROUND_TRIP)
            pose = self.track.camera_at(stamp)
        if pose is None:
            return True
        self.published += 1
        publish(self.session, self.keys.camera, encode_frame(FrameMessage(
            self.keys.vehicle, self.published, CameraFrame(frame.image, pose, frame.intrinsics, stamp))),
            lossless=True)  # a busy depth node slows the folder's play instead of losing a photo
        return True

    def _await_listener(self) -> None:
        """Hold a folder's first photo until its frames have a subscriber (or the node stops)."""
        if not self._frames_out.matching_status.matching:
            _log.info("camera: waiting for a subscriber of %s before playing %s", self.keys.camera,
                      self.settings.source)
        while not (self._frames_out.matching_status.matching or self.stop_event.is_set()):
            self.supervisor.beat("camera")
            self.stop_event.wait(0.05)

    def _camera_pose(self, stamp: float):
        """Wait for a pose at or after ``stamp`` while poses keep coming (a file's frames also wait for the
        first pose: a replayed pose stream may start after the node), then interpolate (None: dropped)."""
        with self._cond:
            while (self.track.newest < stamp and not self.stop_event.is_set()
                   and (time.monotonic() - self._pose_heard <= self.settings.max_gap
                        or (self.kind in ("file", "photos") and not len(self.track)))):
                self.supervisor.beat("camera")
                self._cond.wait(0.05)
            return self.track.camera_at(stamp)

    def _no_frame(self) -> bool:
        """A file's end stops the loop; a device or stream is reopened after a doubling wait."""
        src = self.settings.source
        if self.kind == "file":
            _log.info("camera: video file %s ended after %d frames (%d published, %d dropped)",
                      src, self.read, self.published, self.dropped)
            self.ended.set()
            return False
        if self._cap is not None:
            self._cap.release()
            self._cap = None
        if not self._outage:
            _log.warning("camera %s %s: no frame (unplugged, busy or the stream dropped); reopening with "
                         "waits up to %g s", self.kind, src, self.settings.reconnect_max)
            self._outage = True
        if self.stop_event.wait(self._backoff):
            return True
        self._backoff = min(2.0 * self._backoff, self.settings.reconnect_max)
        self.reconnects += 1
        self._open()
        return True

    # --- status ---------------------------------------------------------------------------

    @property
    def dropped(self) -> int:
        return sum(self.track.dropped.values())

    def status(self) -> dict:
        return {"read": self.read, "published": self.published, "dropped": dict(self.track.dropped),
                "poses": len(self.track), "reconnects": self.reconnects, "rejected": self.rejects.total,
                "source": self.kind if self.kind in ("file", "photos") else "live"}
