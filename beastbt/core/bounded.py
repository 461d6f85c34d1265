"""Logs of bounded size for what a run collects while it runs: a robot on a ``forever`` mission runs for days.

Whatever a run appends to once per tick, step or command must not grow with
the run's length. :class:`HeadTail` keeps the first and the last items of a
log (how it started and what happened last, the two ends a person reads) and
counts those it let go in between; :func:`trim_front` keeps the tail of a
plain list or bytearray, for the emulators' logs of what a driver wrote.
"""

from __future__ import annotations

from collections import deque
from itertools import chain, islice
from typing import Deque, Generic, Iterator, MutableSequence, TypeVar, Union, overload

T = TypeVar("T")


class HeadTail(Generic[T]):
    """A log that keeps its first ``head`` items and its last ``tail`` items, in order, and counts the rest.

    Iterating, ``len``, indexing and slicing see the kept items only (at most
    ``head + tail``); ``dropped`` is how many were let go between the two
    ends, and ``total`` how many were ever appended. Appending is O(1).
    """

    def __init__(self, head: int, tail: int) -> None:
        if head < 0 or tail < 0:
            raise ValueError(f"head and tail must be 0 or more, not {head} and {tail}")
        self.head = head
        """How many of the first items are kept."""
        self.first: list[T] = []
        self.last: Deque[T] = deque(maxlen=tail)
        self.dropped = 0
        """Items let go between the first ``head`` and the last ``tail``."""

    @property
    def tail(self) -> int:
        """How many of the last items are kept."""
        return self.last.maxlen or 0

    @property
    def total(self) -> int:
        """How many items were ever appended (kept and dropped)."""
        return len(self.first) + len(self.last) + self.dropped

    def append(self, item: T) -> None:
        """Add ``item`` at the end; beyond ``head + tail`` items, the oldest of the tail is counted and let go."""
        if len(self.first) < self.head:
            self.first.append(item)
            return
        if len(self.last) == self.tail:
            self.dropped += 1
            if self.tail == 0:
                return
        self.last.append(item)

    def __iter__(self) -> Iterator[T]:
        return chain(self.first, self.last)

    def __reversed__(self) -> Iterator[T]:
        return chain(reversed(self.last), reversed(self.first))

    def __len__(self) -> int:
        return len(self.first) + len(self.last)

    def __bool__(self) -> bool:
        return bool(self.first) or bool(self.last)

    @overload
    def __getitem__(self, index: int) -> T: ...

    @overload
    def __getitem__(self, index: slice) -> list[T]: ...

    def __getitem__(self, index: Union[int, slice]) -> Union[T, list[T]]:
        if isinstance(index, slice):
            start, stop, step = index.indices(len(self))
            if step == 1 and start >= len(self.first):  # the common case, the latest few: no copy of the head
                return list(islice(self.last, start - len(self.first), max(start, stop) - len(self.first)))
            return list(self)[index]
        n = len(self)
        if index < 0:
            index += n
        if not 0 <= index < n:
            raise IndexError("HeadTail index out of range")
        return self.first[index] if index < len(self.first) else self.last[index - len(self.first)]

    def __repr__(self) -> str:
        return f"HeadTail(head={self.head}, tail={self.tail}, kept={len(self)}, dropped={self.dropped})"


def trim_front(log: Union[MutableSequence, bytearray], keep: int) -> None:
    """Let go of the oldest items of ``log`` once it holds more than ``2 * keep``, keeping the last ``keep``.

    Trimming in halves keeps appending O(1) amortised; the log holds between
    ``keep`` and ``2 * keep`` items once it has grown that far.
    """
    if len(log) > 2 * keep:
        del log[:len(log) - keep]


__all__ = ["HeadTail", "trim_front"]
