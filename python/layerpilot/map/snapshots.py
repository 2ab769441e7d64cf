"""Snapshot store: the last few good map snapshots, written atomically, loaded newest good first.

The map server writes a snapshot now and then and reloads the newest one after a restart. A crash,
a full disk or a damaged file must never cost the whole map, and must never pass unnoticed:

- each save goes to its own uniquely named temporary file (fsynced, with an integrity footer, see
  ``layerpilot.map.files``) and is renamed into place, so concurrent saves all succeed and a reader
  sees a whole snapshot or the previous one;
- older snapshots rotate to ``map.1.ot``, ``map.2.ot``, ... so damage to the newest leaves a good
  one behind;
- loading checks the newest first; a damaged file is renamed to ``<name>.damaged-<timestamp>``,
  logged as an ERROR on ``layerpilot.map`` and the next older snapshot is tried.
"""

from __future__ import annotations

import logging
import math
import os
import threading
from datetime import datetime
from pathlib import Path

from layerpilot.map.files import MapFileError, commit, fsync_dir, write_temp
from layerpilot.map.voxel_map import VoxelMap

_log = logging.getLogger("layerpilot.map")
_locks: dict[Path, threading.Lock] = {}
_locks_guard = threading.Lock()


def _lock_for(path: Path) -> threading.Lock:
    """One lock per snapshot path in this process, shared by every store on it (callers may make a store per save)."""
    with _locks_guard:
        return _locks.setdefault(path.resolve(), threading.Lock())


class SnapshotStore:
    """The snapshots of one map: ``path`` is the newest, ``keep`` of them are kept."""

    def __init__(self, path: Path, keep: int = 3) -> None:
        path = Path(path)
        if path.suffix != ".ot":
            raise ValueError(f"path: snapshots are .ot files, got {path.name}")
        if keep < 1:
            raise ValueError(f"keep: must be >= 1, got {keep}")
        self.path = path
        self.keep = keep
        self._lock = _lock_for(path)

    def paths(self) -> list[Path]:
        """Snapshot names, newest first: map.ot, map.1.ot, ..., whether they exist or not."""
        stem, suffix = self.path.stem, self.path.suffix
        return [self.path] + [self.path.with_name(f"{stem}.{i}{suffix}") for i in range(1, self.keep)]

    def save(self, voxel_map: VoxelMap) -> int:
        """Write ``voxel_map`` as the newest snapshot and rotate the older ones; returns the bytes written.

        Saves are serialized, so the newest snapshot is always the map of the last save to start.
        The new file is complete and fsynced before any older snapshot is renamed.
        """
        with self._lock:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp, size = write_temp(self.path, voxel_map.to_bytes(".ot"))
            try:
                self._rotate()
                commit(tmp, self.path)
            except BaseException:
                tmp.unlink(missing_ok=True)
                raise
            return size

    def _rotate(self) -> None:
        """Shift the existing snapshots one name older (closing gaps that damaged ones left).

        The oldest beyond ``keep`` is overwritten.
        """
        names = self.paths()
        existing = [p for p in names if p.exists()][: self.keep - 1]
        for i in reversed(range(len(existing))):
            os.replace(existing[i], names[i + 1])
        if existing:
            fsync_dir(self.path.parent)

    def load_newest_good(self, resolution: float) -> tuple[VoxelMap | None, list[str]]:
        """The newest snapshot that is whole and has ``resolution``, or None; and what happened, one line per file.

        Never raises for damage and never returns part of a map: a damaged snapshot is moved aside
        and logged as an ERROR, a snapshot of another resolution is logged as an ERROR and left in
        place, and the next older one is tried. None means no usable snapshot: the caller starts
        with an empty map (and says so when the events are not empty).
        """
        events: list[str] = []
        with self._lock:
            for path in self.paths():
                voxel_map = self._load_one(path, resolution, events)
                if voxel_map is not None:
                    return voxel_map, events
        return None, events

    def _load_one(self, path: Path, resolution: float, events: list[str]) -> VoxelMap | None:
        if not path.exists():
            return None
        try:
            voxel_map = VoxelMap.load(path)
        except FileNotFoundError:  # removed by another process since exists()
            return None
        except MapFileError as exc:
            _error(events, f"damaged map snapshot {exc}; {_move_aside(path)}")
            return None
        if not math.isclose(voxel_map.resolution, resolution, rel_tol=1e-6):
            _error(events, f"map snapshot {path} has resolution {voxel_map.resolution:g} m, the map needs "
                           f"{resolution:g} m: not loaded")
            return None
        events.append(f"map snapshot {path} loaded ({path.stat().st_size} bytes)")
        return voxel_map


def _error(events: list[str], event: str) -> None:
    _log.error("%s", event)
    events.append(event)


def _move_aside(path: Path) -> str:
    """Rename a damaged snapshot to ``<name>.damaged-<timestamp>`` (kept for inspection, never loaded again)."""
    stamp = f"{datetime.now():%Y%m%dT%H%M%S}"
    aside = path.with_name(f"{path.name}.damaged-{stamp}")
    n = 1
    while aside.exists():
        n += 1
        aside = path.with_name(f"{path.name}.damaged-{stamp}-{n}")
    try:
        os.replace(path, aside)
    except OSError as exc:
        return f"could not move it aside: {exc.strerror or exc}"
    return f"moved aside to {aside.name}"
