"""Mission recordings: every bus message in an MCAP file with its protobuf schema, and reading them back.

A recording is what Foxglove, Lichtblick or the ``mcap`` tools open: one MCAP channel per
bus key (``layerpilot/uav1/cloud``), protobuf encoding, the schema of proto/messages.proto
(``layerpilot.PointCloud``, ...) as a FileDescriptorSet, and the payloads exactly as they
travelled. The mission file is kept as MCAP metadata (``layerpilot`` / ``mission``), so a
replay flies the same map settings and behavior area.

With a ``translate`` function (``layerpilot.ros2.recording.ros2_channels``) the recording also
holds ROS 2 channels (``ros2msg`` schemas, CDR messages: what ``ros2 bag`` and Foxglove read as a
ROS 2 bag), beside the protobuf ones or, with ``protobuf=False``, instead of them.

Writing happens on one thread behind a queue (a Zenoh callback never waits on compression);
chunks carry CRCs. When the file cannot be written (a full disk, a lost mount) the writer logs it
once, drops and counts what is queued and every later message, and ``error`` says what happened:
closing never raises, the mission goes on. Reading is sequential and stops at the first damage (a truncated file
after a crash, a flipped bit in a chunk) with one warning saying where; messages whose schema
is not one of ours are skipped and counted.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import zenoh
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.well_known import MessageEncoding
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import register_schema

from layerpilot.bus import keys
from layerpilot.bus.messages import parse
from layerpilot.bus.proto_gen import messages_pb2 as pb
from layerpilot.bus.reject import BadMessage, Rejects

_log = logging.getLogger("layerpilot.recording")
SCHEMAS = {"camera": pb.CameraFrame, "cloud": pb.PointCloud, "pose": pb.VehicleState, "layers": pb.LayerSet,
           "decision": pb.Decision, "waypoint": pb.Waypoint, "state": pb.MissionState,
           "health": pb.NodeHealth}  # health: layerpilot/<vehicle>/health/<node>
KNOWN_SCHEMAS = {cls.DESCRIPTOR.full_name for cls in SCHEMAS.values()}
METADATA = "layerpilot"
CHUNK_SIZE = 256 << 10  # bytes: a crash loses at most the last chunk
MAX_QUEUED_BYTES = 512 << 20  # payload bytes waiting for the writer; beyond, new messages are dropped and counted


@dataclass(frozen=True)
class ExtraMessage:
    """A message of another encoding written for a bus message (a ROS 2 one: ``ros2msg`` schema, CDR data)."""

    topic: str
    schema_name: str
    schema_encoding: str
    schema: str  # the schema's text
    message_encoding: str
    data: bytes


Translate = Callable[[str, bytes], list[ExtraMessage]]  # (bus topic, payload) -> messages to write beside it


def topic_of(key: str) -> str:
    """The topic of a concrete key ``layerpilot/<vehicle>/<topic>`` or ``layerpilot/<vehicle>/health/<node>``
    (BadMessage when it is none of ours)."""
    parts = key.split("/")
    health = len(parts) == 4 and parts[2] == "health" and parts[3] in keys.NODES
    if parts[0] != keys.PREFIX or not (health or (len(parts) == 3 and parts[2] in keys.TOPICS)):
        raise BadMessage("unknown key", f"{key!r} is not layerpilot/<vehicle>/<{'|'.join(keys.TOPICS)}> "
                                        f"or layerpilot/<vehicle>/health/<{'|'.join(keys.NODES)}>")
    keys.check_vehicle(parts[1])
    return parts[2]


class RecordingWriter:
    """An MCAP file being written: ``write(key, payload)`` from any thread, ``close()`` once."""

    def __init__(self, path: str | Path, mission_text: str = "", translate: Translate | None = None,
                 protobuf: bool = True) -> None:
        self.path = Path(path)
        self._translate, self._protobuf = translate, protobuf
        if self.path.parent.exists() and not self.path.parent.is_dir():
            raise NotADirectoryError(f"cannot write the recording {self.path}: {self.path.parent} is not a folder")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "wb")
        except OSError as exc:
            raise type(exc)(f"cannot write the recording {self.path}: {exc.strerror} ({exc.filename})") from None
        self._mcap = Writer(self._file, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD, enable_crcs=True)
        self._mcap.start(profile="", library="layerpilot")
        if mission_text:
            self._mcap.add_metadata(METADATA, {"mission": mission_text})
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._sequence: Counter[str] = Counter()
        self.written: Counter[str] = Counter()  # messages per key
        self.rejects = Rejects(_log)
        self.dropped = 0  # the writer fell behind by more than MAX_QUEUED_BYTES, or had failed
        self.error = ""  # why the file could not be written ("" while it can)
        self._queue: deque[tuple[str, bytes, int]] = deque()
        self._queued_bytes = 0
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._drain, name="recording-writer", daemon=True)
        self._thread.start()

    def write(self, key: str, payload: bytes, log_time: int | None = None) -> None:
        """Queue one bus message; one that is not ours (unknown key, not its protobuf) is rejected and counted."""
        try:
            parse(SCHEMAS[topic_of(key)], payload)
        except BadMessage as exc:
            self.rejects.reject(key, exc)
            return
        with self._cond:
            if self._closed:
                return
            if self.error or self._queued_bytes + len(payload) > MAX_QUEUED_BYTES:
                self.dropped += 1
                return
            self._queue.append((key, payload, time.time_ns() if log_time is None else log_time))
            self._queued_bytes += len(payload)
            self._cond.notify()

    def _drain(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._queue or self._closed)
                if not self._queue:
                    return
                key, payload, stamp = self._queue.popleft()
                self._queued_bytes -= len(payload)
            try:
                self._add(key, payload, stamp)
            except Exception as exc:  # OSError mostly (ENOSPC); any failure leaves the MCAP writer unusable
                self._fail(exc, after=f"{sum(self.written.values())} messages", lost=1)
                return

    def _fail(self, exc: Exception, after: str, lost: int = 0) -> None:
        """Remember the first failure, log it once, drop (and count) what waits: no later write can succeed."""
        with self._cond:
            if not self.error:
                self.error = f"{self.path}: {type(exc).__name__}: {exc} (after {after})"
                _log.error("recording failed: %s; dropping every later message", self.error)
            self.dropped += lost + len(self._queue)  # lost: the message being written when it failed
            self._queue.clear()
            self._queued_bytes = 0

    def _add(self, key: str, payload: bytes, stamp: int) -> None:
        topic = topic_of(key)
        if self._translate is not None:
            try:
                extra = self._translate(topic, payload)
            except BadMessage as exc:
                self.rejects.reject(key, exc)
                extra = []
            for m in extra:
                self._add_extra(m, stamp)
        if not self._protobuf:
            return
        if key not in self._channels:
            cls = SCHEMAS[topic]
            if topic not in self._schemas:
                self._schemas[topic] = register_schema(self._mcap, cls)
            self._channels[key] = self._mcap.register_channel(key, MessageEncoding.Protobuf, self._schemas[topic])
        self._mcap.add_message(self._channels[key], log_time=stamp, data=payload, publish_time=stamp,
                               sequence=self._sequence[key])
        self._sequence[key] += 1
        self.written[key] += 1

    def _add_extra(self, m: ExtraMessage, stamp: int) -> None:
        if m.topic not in self._channels:
            if m.schema_name not in self._schemas:
                self._schemas[m.schema_name] = self._mcap.register_schema(m.schema_name, m.schema_encoding,
                                                                          m.schema.encode())
            self._channels[m.topic] = self._mcap.register_channel(m.topic, m.message_encoding,
                                                                  self._schemas[m.schema_name])
        self._mcap.add_message(self._channels[m.topic], log_time=stamp, data=m.data, publish_time=stamp,
                               sequence=self._sequence[m.topic])
        self._sequence[m.topic] += 1
        self.written[m.topic] += 1

    def close(self) -> None:
        """Write what is queued, then the index and footer (the file is complete only after this);
        a failure is not raised but kept in ``error``."""
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._cond.notify()
        self._thread.join()
        try:
            if not self.error:
                self._mcap.finish()
        except Exception as exc:
            self._fail(exc, after="the last message, writing the index and footer")
        try:
            self._file.close()
        except OSError as exc:  # the buffered tail could not be flushed
            self._fail(exc, after="writing the end of the file")

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Recorder:
    """Every message of a mission's bus (``layerpilot/**``) into a recording, until ``stop()``."""

    def __init__(self, session: zenoh.Session, path: str | Path, mission_text: str = "",
                 translate: Translate | None = None, protobuf: bool = True) -> None:
        self.writer = RecordingWriter(path, mission_text, translate, protobuf)
        self._sub = session.declare_subscriber(f"{keys.PREFIX}/**", self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self.writer.write(str(sample.key_expr), sample.payload.to_bytes())

    def stop(self) -> dict:
        """Stop listening, finish the file; returns what was written (messages per key, rejects, drops,
        and ``error``: why the file is incomplete, "" when it is whole)."""
        self._sub.undeclare()
        self.writer.close()
        return {"path": str(self.writer.path), "messages": dict(self.writer.written),
                "rejected": self.writer.rejects.total, "dropped": self.writer.dropped, "error": self.writer.error}


@dataclass(frozen=True)
class RecordedMessage:
    key: str  # the bus key it travelled on
    topic: str  # camera, cloud, pose, ...
    data: bytes  # the protobuf payload as it travelled
    log_time: int  # ns (wall clock of the recorder)


class RecordingReader:
    """Sequential reading of a recording: ``messages()`` yields ours in file order; after it,
    ``damage`` says where reading stopped early (empty: read to the end), ``unknown_schemas`` counts
    the skipped messages per schema name (``ros2_messages`` those of ROS 2 channels), ``mission_text`` is
    the recorded mission file (or "")."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"recording: no such file: {self.path}")
        self.damage = ""
        self.unknown_schemas: Counter[str] = Counter()
        self.counts: Counter[str] = Counter()  # messages yielded per key
        self.ros2_messages = 0  # ROS 2 channels' messages, skipped (ros2.recording writes them for ROS tools)
        self.mission_text = ""
        self.size = self.path.stat().st_size
        self.position = 0  # bytes read so far (progress)

    def messages(self) -> Iterator[RecordedMessage]:
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        with open(self.path, "rb") as f:
            reader = StreamReader(f, validate_crcs=True, record_size_limit=1 << 30)
            try:
                for record in reader.records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        channels[record.id] = record
                    elif isinstance(record, Metadata) and record.name == METADATA:
                        self.mission_text = record.metadata.get("mission", "")
                    elif isinstance(record, Message):
                        if (message := self._ours(record, channels, schemas)) is not None:
                            self.position = f.tell()
                            yield message
            except Exception as exc:  # truncated, bad CRC, a chunk that does not decompress: all damage
                what = str(exc) or "the file ends in the middle of a record"
                self.damage = (f"{self.path}: damaged near byte {f.tell()} ({type(exc).__name__}: {what}); "
                               f"read {sum(self.counts.values())} messages before it")
                _log.warning("recording %s", self.damage)
        if self.unknown_schemas:
            _log.warning("recording %s: skipped %d messages of unknown schemas %s", self.path,
                         sum(self.unknown_schemas.values()), dict(self.unknown_schemas))

    def _ours(self, record: Message, channels: dict[int, Channel],
              schemas: dict[int, Schema]) -> RecordedMessage | None:
        channel = channels.get(record.channel_id)
        schema = schemas.get(channel.schema_id) if channel is not None else None
        name = schema.name if schema is not None else f"<channel {record.channel_id} without schema>"
        try:
            topic = topic_of(channel.topic) if channel is not None else ""
        except BadMessage:
            topic = ""
        if schema is not None and schema.encoding == "ros2msg":  # a ROS 2 channel beside ours: not replayed
            self.ros2_messages += 1
            return None
        if (schema is None or schema.encoding != "protobuf" or name not in KNOWN_SCHEMAS or not topic
                or SCHEMAS[topic].DESCRIPTOR.full_name != name):
            self.unknown_schemas[name] += 1
            return None
        self.counts[channel.topic] += 1
        return RecordedMessage(channel.topic, topic, bytes(record.data), record.log_time)
