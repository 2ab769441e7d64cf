"""Map files on disk: atomic writes that end in an integrity footer, and reads that check it.

A file layerpilot writes is OctoMap's own stream followed by one footer line::

    \\nlayerpilot-integrity sha256 <64 hex digits> size <20 digits>\\n

giving the SHA-256 and the length of the stream before it. OctoMap's readers stop where the node
stream ends, so Debian's octomap-tools read the file as it is; layerpilot checks the footer and so
also catches damage that still parses (garbage inside node data). A footer rather than a sidecar
file: it travels with the map when the map is copied, and it is renamed into place together with
the map, so a crash can never leave a map and a check that disagree.
"""

from __future__ import annotations

import hashlib
import os
import re
import uuid
from pathlib import Path

FOOTER_MARK = b"\nlayerpilot-integrity sha256 "
_FOOTER = re.compile(re.escape(FOOTER_MARK) + rb"([0-9a-f]{64}) size ([0-9]{20})\n")
FOOTER_SIZE = len(FOOTER_MARK) + 64 + len(b" size ") + 20 + 1


class MapFileError(ValueError):
    """A map file that is truncated, damaged or not a map; the message is one line naming the file."""


def footer(stream: bytes) -> bytes:
    """The integrity footer of ``stream``."""
    return FOOTER_MARK + f"{hashlib.sha256(stream).hexdigest()} size {len(stream):020d}\n".encode()


def write_temp(path: Path, stream: bytes) -> tuple[Path, int]:
    """Write ``stream`` and its footer to a new, uniquely named file beside ``path`` and fsync it.

    Unique names let concurrent writers of one path all succeed; the caller renames the file into
    place (``commit``). Returns the temporary path and the bytes written.
    """
    if not path.parent.is_dir():
        raise FileNotFoundError(f"{path}: no folder {path.parent} to write the map into")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:12]}.tmp")
    data = footer(stream)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(fd, "wb") as f:
            f.write(stream)
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp, len(stream) + len(data)


def commit(tmp: Path, path: Path) -> None:
    """Rename ``tmp`` over ``path`` and fsync the directory, so the rename survives a power cut."""
    os.replace(tmp, path)
    fsync_dir(path.parent)


def fsync_dir(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(path: Path, stream: bytes) -> int:
    """Write ``stream`` with its footer to ``path``: readers see the old file or the new one, never a part."""
    tmp, size = write_temp(path, stream)
    try:
        commit(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return size


def read_checked(path: Path) -> memoryview:
    """The OctoMap stream of ``path`` without its footer, once the footer (if any) agrees with it.

    A file without a footer (stock OctoMap, or one whose footer was cut off) is returned whole; the
    C++ parser then validates its structure. Raises MapFileError for an unreadable file or a footer
    that disagrees.
    """
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MapFileError(f"{path}: cannot read: {exc.strerror or exc}") from None
    body = len(data) - FOOTER_SIZE
    found = _FOOTER.fullmatch(data, body) if body >= 0 else None
    if found is None:
        if FOOTER_MARK in data[-FOOTER_SIZE:]:
            raise MapFileError(f"{path}: truncated: the integrity footer is cut short")
        return memoryview(data)
    size, digest = int(found[2]), found[1].decode()
    if size != body:
        raise MapFileError(f"{path}: damaged: the footer says the map stream has {size} bytes, it has {body}")
    if hashlib.sha256(memoryview(data)[:body]).hexdigest() != digest:
        raise MapFileError(f"{path}: damaged: the map stream's SHA-256 differs from its footer (garbled bytes)")
    return memoryview(data)[:body]
