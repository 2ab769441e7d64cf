"""A bounded hand-over from a Zenoh callback to one worker thread: the oldest item is dropped when full."""

from __future__ import annotations

import threading
from collections import deque
from typing import Generic, TypeVar

T = TypeVar("T")


class DropOldest(Generic[T]):
    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError(f"size: must be >= 1, got {size}")
        self.size = size
        self._items: deque[T] = deque()
        self._cond = threading.Condition()
        self._closed = False
        self.received = 0
        self.dropped = 0

    def put(self, item: T) -> None:
        with self._cond:
            self.received += 1
            if len(self._items) >= self.size:
                self._items.popleft()
                self.dropped += 1
            self._items.append(item)
            self._cond.notify()

    def get(self, timeout: float | None = None) -> T | None:
        """The oldest item, waiting for one; None once closed (the worker then exits) or after ``timeout``."""
        with self._cond:
            self._cond.wait_for(lambda: self._items or self._closed, timeout)
            return None if self._closed or not self._items else self._items.popleft()

    def rest(self) -> list[T]:
        """The items still queued, taken out (what the worker of a closed queue left)."""
        with self._cond:
            items, self._items = list(self._items), deque()
            return items

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def __len__(self) -> int:
        with self._cond:
            return len(self._items)
