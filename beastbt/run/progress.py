"""How far a mission has got: steps done out of the steps a full run takes, and an ETA where it can be known.

Read from the tree's state on demand (the console and the status line ask a
few times a second; nothing is counted per tick). A *step* here is a leaf run
to completion: ``repeat: {times: 3}`` over two steps plans six. The plan
follows the first branch of a choice (``if``/``else``, a fallback) and one
attempt of a ``retry``; a loop that has no fixed count (``forever``,
``while``) has no total, and then no ETA either.

The ETA is the steps left at the pace of the steps done (the mission time when
the count last changed over the count), less the time the running step has
run so far, but never less than the steps after the running one at that pace:
it falls as a step runs and holds once the step has run longer than the pace,
instead of growing every second through one long step. The only state it needs
is when the count last changed (:class:`ProgressClock`, one per tree, kept
beside it).
"""

from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass
from typing import Optional

import py_trees

from beastbt.behaviours.flow import RepeatTimes, WhileLoop

Status = py_trees.common.Status
Behaviour = py_trees.behaviour.Behaviour
_ENDED = (Status.SUCCESS, Status.FAILURE)


@dataclass(frozen=True)
class Progress:
    """Steps ``done`` of ``total`` (None: unbounded), and the mission seconds left at the pace so far (None: unknown;
    0 when every step is done; see the module docstring)."""

    done: int
    total: Optional[int]
    eta_s: Optional[float]

    def as_dict(self) -> dict:
        """``{done, total, eta_s}`` for JSON."""
        return {"done": self.done, "total": self.total,
                "eta_s": None if self.eta_s is None else round(self.eta_s, 1)}

    def text(self) -> str:
        """``3/12 steps, ETA 40 s`` (or ``3 steps`` when there is no total)."""
        if self.total is None:
            return f"{self.done} steps"
        eta = f", ETA {self.eta_s:.0f} s" if self.eta_s is not None and self.done < self.total else ""
        return f"{self.done}/{self.total} steps{eta}"


def planned(node: Behaviour) -> Optional[int]:
    """Leaf runs in one full pass of ``node`` (None: no fixed number)."""
    if not node.children:
        return 1
    if isinstance(node, WhileLoop):
        return None
    if isinstance(node, RepeatTimes):
        inner = planned(node.decorated)
        return None if inner is None or node.num_success < 0 else inner * node.num_success
    if isinstance(node, py_trees.decorators.Decorator):
        return planned(node.children[0])
    if isinstance(node, py_trees.composites.Sequence):
        counts = [planned(c) for c in node.children]
        return None if None in counts else sum(c for c in counts if c is not None)
    # A choice or a parallel: its first branch (the plan), or the longest of the parallel ones.
    counts = [planned(c) for c in node.children]
    if isinstance(node, py_trees.composites.Parallel):
        return None if None in counts else max(c for c in counts if c is not None)
    return counts[0]


def done(node: Behaviour) -> int:
    """Leaf runs completed in ``node``'s current pass."""
    status = node.status
    if not node.children:
        return 1 if status in _ENDED else 0
    if status == Status.INVALID:
        return 0
    if isinstance(node, WhileLoop):
        per_pass = planned(node.body) or 0
        return node.passes * per_pass + (done(node.body) if node.in_pass else 0)
    if isinstance(node, RepeatTimes):
        child = node.decorated
        per_pass = planned(child) or 0
        if status == Status.SUCCESS:
            return node.success * per_pass
        # Right after a pass the child still shows SUCCESS and the pass is already in the count.
        return node.success * per_pass + (0 if child.status == Status.SUCCESS else done(child))
    if isinstance(node, py_trees.decorators.Decorator):
        return done(node.children[0])
    if isinstance(node, py_trees.composites.Sequence):
        if status == Status.SUCCESS:
            return planned(node) or sum(done(c) for c in node.children)
        total = 0
        for child in node.children:
            if child is node.current_child:
                return total + done(child)
            total += planned(child) or done(child)
        return total
    if isinstance(node, py_trees.composites.Parallel):
        return max((done(c) for c in node.children), default=0)
    current = node.current_child
    return done(current) if current is not None else 0


class ProgressClock:
    """When the count of steps done last changed (mission time, s): the start of the running step, as far as
    progress can tell (it is looked at when asked, so it is late by at most the time between two looks)."""

    def __init__(self) -> None:
        self._seen: Optional[tuple[int, float]] = None
        """(count, mission time it was first seen at); one tuple, swapped whole (the reads need no lock)."""

    def since(self, count: int, elapsed_s: float) -> float:
        """The mission time (s) at which ``count`` steps were first seen done (``elapsed_s`` when it is new)."""
        seen = self._seen
        if seen is None or seen[0] != count or seen[1] > elapsed_s:
            seen = self._seen = (count, elapsed_s)
        return seen[1]


_CLOCKS: "weakref.WeakKeyDictionary[Behaviour, ProgressClock]" = weakref.WeakKeyDictionary()
_CLOCKS_LOCK = threading.Lock()


def clock_of(root: Behaviour) -> ProgressClock:
    """The tree's :class:`ProgressClock` (made on first use; it goes with the tree), shared by whoever asks."""
    with _CLOCKS_LOCK:
        clock = _CLOCKS.get(root)
        if clock is None:
            clock = _CLOCKS[root] = ProgressClock()
        return clock


def eta_s(count: int, total: int, elapsed_s: float, since_s: float) -> Optional[float]:
    """Mission seconds left (None: unknown, no step done yet) with ``count`` of ``total`` steps done after
    ``elapsed_s``, the count reached at ``since_s``: the steps left at the pace of those done, less the time the
    running step has taken, never below the steps after it at that pace."""
    if count <= 0 or since_s <= 0:
        return None
    if count >= total:
        return 0.0
    pace = since_s / count
    running = max(0.0, elapsed_s - since_s)
    return max(pace * (total - count) - running, pace * (total - count - 1))


def progress_of(root: Behaviour, elapsed_s: float, clock: Optional[ProgressClock] = None) -> Progress:
    """The mission's progress after ``elapsed_s`` seconds of mission time; ``clock``: when the count last changed
    (default: the tree's own, :func:`clock_of`)."""
    total = planned(root)
    count = done(root)
    if total is not None:
        count = min(count, total)
    eta = None
    if total is not None and elapsed_s > 0:
        since = (clock if clock is not None else clock_of(root)).since(count, elapsed_s)
        eta = eta_s(count, total, elapsed_s, since)
    return Progress(count, total, eta)


__all__ = ["Progress", "ProgressClock", "planned", "done", "progress_of", "clock_of", "eta_s"]
