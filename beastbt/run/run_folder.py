"""The run folder: ``runs/<UTC time>_<mission>/`` with the summary, the event log and snapshots.

When the mission file's name differs from the mission's ``mission:`` name,
both are in the folder's name (``<time>_<file>_<mission>``), so a run is
found by either.
"""

from __future__ import annotations

import datetime as _dt
import errno
import json
import os
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

from beastbt.core.clock import utc_now



def save_jpeg(folder: Path, name: str, frame: Any) -> str:
    """Save a camera frame as ``folder/<name>.jpg`` (``-2``, ``-3``... when taken); return its path."""
    target = folder / f"{name}.jpg"
    n = 1
    while target.exists():
        n += 1
        target = folder / f"{name}-{n}.jpg"
    import cv2  # only a run that takes snapshots needs OpenCV here
    if not cv2.imwrite(str(target), frame.image):
        try:
            target.unlink()  # a partial JPEG (a full disk) is no snapshot
        except OSError:
            pass
        raise OSError(errno.EIO, f"could not write {target} (a full disk?)")
    return str(target)


def temporary_snapshots(mission: str) -> Callable[[str, Any], str]:
    """A snapshot saver for a run that is not recorded: a temporary folder, made at the first snapshot."""
    folder: list[Path] = []

    def save(name: str, frame: Any) -> str:
        if not folder:
            import tempfile
            folder.append(Path(tempfile.mkdtemp(prefix=f"beastbt-{_safe(mission)}-snapshots-")))
        return save_jpeg(folder[0], name, frame)
    return save


def _safe(name: str) -> str:
    """``name`` as a file name: letters of any alphabet, digits, _ and - kept, anything else as _."""
    return re.sub(r"[^\w-]", "_", name)


NAME_CHARS = 48
"""The most characters of a mission's name a run folder's name keeps (file systems allow 255 bytes; people read less)."""


class RunFolderUnavailable(Exception):
    """The run folder cannot be made (a full disk, no permission): the run does not start; says what to do."""


@dataclass
class RunFolder:
    """Where one run's files go. Writers that record more (MCAP) add themselves to ``finishers``."""

    path: Path
    finishers: list[Callable[[dict], None]] = field(default_factory=list)
    summary_written: bool = False
    """``summary.json`` was written whole by :meth:`finish`."""
    lock_fd: Optional[int] = None
    """Holds the folder's ``.running`` lock while the run runs (:mod:`beastbt.run.retention`: never pruned)."""

    @classmethod
    def create(cls, runs_dir: str, mission: str, clock: Any,
               calendar: Callable[[], _dt.datetime] = utc_now) -> "RunFolder":
        """Make ``runs_dir/<UTC time>_<mission>/``, as the README says (a suffix keeps two runs in one second apart).

        The mission's name is cut to :data:`NAME_CHARS` characters. ``calendar``
        gives the date and time in the name (UTC).
        """
        stamp = calendar().strftime("%Y%m%dT%H%M%SZ")
        base = Path(runs_dir) / f"{stamp}_{_safe(mission)[:NAME_CHARS]}"
        path = base
        n = 1
        while path.exists():
            n += 1
            path = Path(f"{base}-{n}")
        while True:
            try:
                path.mkdir(parents=True)
                break
            except FileExistsError:  # another process (beastbt test -j N) made it since: the next suffix
                n += 1
                path = Path(f"{base}-{n}")
            except OSError as exc:
                raise RunFolderUnavailable(f"cannot make the run folder {path} ({exc.strerror or exc}): free some "
                                           f"space, give --runs-dir on another disk, or run with --no-record") from None
        from beastbt.run.retention import hold_running_lock
        try:
            lock_fd: Optional[int] = hold_running_lock(path)
        except OSError:
            lock_fd = None  # a file system without locks: the run is still recorded, only not guarded from pruning
        return cls(path, lock_fd=lock_fd)

    def save_snapshot(self, name: str, frame: Any) -> str:
        """Save a :class:`~beastbt.blackboard.types.CameraFrame` as ``<name>.jpg``; return its path."""
        return save_jpeg(self.path, name, frame)

    def finish(self, summary: dict) -> list[str]:
        """Write ``summary.json`` and ``events.log``, then let the other writers finish.

        Returns what could not be written (a full disk), one sentence each; the
        rest is written all the same. A ``summary.json`` that could not be
        written is left empty (``beastbt runs``: no summary), never half written.
        """
        problems = []
        for name, text in (("summary.json", json.dumps(summary, indent=2) + "\n"),
                           ("events.log", events_log_text(summary["events"]))):
            problem = save_text(self.path / name, text)
            if problem is not None:
                problems.append(problem)
            elif name == "summary.json":
                self.summary_written = True
        for fin in self.finishers:
            try:
                fin(summary)
            except Exception as exc:  # noqa: BLE001 - the summary is kept whatever a writer does
                problems.append(f"could not finish the recording in {self.path}: {exc!r}")
        self.release()
        return problems

    def release(self) -> None:
        """Let go of the ``.running`` lock: the run is finished, and may be pruned like any other."""
        if self.lock_fd is not None:
            os.close(self.lock_fd)
            self.lock_fd = None
            try:
                os.unlink(self.path / ".running")  # a finished run's folder holds what it recorded, nothing else
            except OSError:
                pass


def events_log_text(events: list[dict]) -> str:
    """``events.log``: one line per event of the summary (time s, kind, text)."""
    return "".join(f"{e['time_s']:10.3f}  {e['kind']:<14} {e['text']}\n" for e in events)


def save_text(path: Path, text: str) -> Optional[str]:
    """Write ``text`` to ``path`` (UTF-8); None when done, else why not (a full disk: the file is left empty)."""
    try:
        Path(path).write_text(text, encoding="utf-8")
        return None
    except OSError as exc:
        try:
            os.truncate(path, 0)  # not half a JSON document: empty says "not written" plainly
        except OSError:
            pass
        if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
            try:
                free = f" ({shutil.disk_usage(Path(path).parent).free / 1e6:.1f} MB free)"
            except OSError:
                free = ""
            return f"could not write {path}: the disk is full{free}"
        return f"could not write {path}: {exc.strerror or exc!r}"
