"""Keeping the runs folder from filling the disk: prune the oldest finished runs, never a running or a kept one.

A robot that records every run (as beastbt does) fills its SD card in weeks. The profile's ``runs:`` section
(:class:`RunsPolicy`; ``--keep-runs N`` on ``run`` and ``serve``) says what to keep: the newest ``keep`` runs, at
most ``max_total_mb`` in all, and at least ``min_free_mb`` free on the disk. Each run, when its folder is made,
prunes the oldest finished runs until all three hold (:func:`prune_runs`); the same floor stops its recording
cleanly should the disk still fill during the run, and the mission goes on.

Never pruned: the run that is running (its folder holds an exclusive lock on ``.running`` while it runs, so a
second beastbt on the same folder sees it too; a run that died left the lock free and is finished), and a run
marked ``keep`` (a ``KEEP`` file in its folder: ``beastbt runs keep RUN``). Every prune is a line in
``RUNS_DIR/prune.log`` and an event of the run that pruned.
"""

from __future__ import annotations

import fcntl
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from beastbt.core.clock import utc_now

KEEP_MARKER = "KEEP"
"""A file of this name in a run folder keeps it from pruning (its text: why, or empty)."""
RUNNING_LOCK = ".running"
"""A run folder's lock file: locked (flock, exclusive) while its run runs."""
PRUNE_LOG = "prune.log"
"""In the runs folder: one line per pruned run (UTC time, folder, MB, reason)."""
MB = 1_000_000
"""A megabyte, as the profile's knobs count them (10^6 bytes, as ``df -H``)."""


@dataclass(frozen=True)
class RunsPolicy:
    """What the runs folder keeps (profile ``runs:``; every knob optional, None = no limit of that kind)."""

    keep: Optional[int] = None
    """The newest finished runs kept (count); older ones are pruned. Kept and running runs do not count."""
    max_total_mb: Optional[float] = None
    """The most the runs folder may hold (megabytes, 10^6 bytes); the oldest finished runs go first."""
    min_free_mb: float = 50.0
    """Free space kept on the runs folder's disk (megabytes): old runs are pruned to keep it, and a recording
    stops cleanly (the mission goes on) rather than go below it. 0 turns the floor off."""

    @classmethod
    def from_section(cls, section: Optional[dict], keep_runs: Optional[int] = None) -> "RunsPolicy":
        """The policy of a profile's ``runs:`` section (its values checked by the schema), ``keep_runs`` (the
        command line's ``--keep-runs``) winning over its ``keep``."""
        section = section or {}
        keep = keep_runs if keep_runs is not None else section.get("keep")
        total = section.get("max_total_mb")
        return cls(keep=None if keep is None else int(keep), max_total_mb=None if total is None else float(total),
                   min_free_mb=float(section.get("min_free_mb", cls.min_free_mb)))


@dataclass(frozen=True)
class PrunedRun:
    """One run folder that was deleted: its name, its size (bytes) and the rule that pruned it."""

    name: str
    size_bytes: int
    reason: str


@dataclass(frozen=True)
class RunFolderInfo:
    """A run folder as the pruning sees it."""

    path: Path
    size_bytes: int
    kept: bool
    running: bool


def folder_size(path: Path) -> int:
    """Bytes of the regular files below ``path`` (links not followed)."""
    total = 0
    for root, _dirs, files in os.walk(path):
        for name in files:
            try:
                st = os.lstat(os.path.join(root, name))
            except OSError:
                continue
            total += st.st_size
    return total


def is_running(folder: Path) -> bool:
    """Whether a run holds ``folder``'s lock now (a folder without a lock file is not running)."""
    lock = folder / RUNNING_LOCK
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)
    return False


def hold_running_lock(folder: Path) -> int:
    """Lock ``folder`` as running for as long as the returned descriptor stays open (closing it unlocks)."""
    fd = os.open(folder / RUNNING_LOCK, os.O_WRONLY | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return fd


def run_folders(runs_dir: Path) -> list[RunFolderInfo]:
    """The run folders of ``runs_dir``, oldest first (their names start with the UTC time they began)."""
    if not runs_dir.is_dir():
        return []
    found = []
    for entry in sorted(runs_dir.iterdir(), key=lambda p: (p.name, p.stat().st_mtime if p.exists() else 0)):
        if not entry.is_dir() or entry.is_symlink() or entry.name.startswith("."):
            continue
        if not ((entry / "summary.json").exists() or (entry / "run.mcap").exists() or (entry / RUNNING_LOCK).exists()):
            continue  # not a run folder: never touched
        found.append(RunFolderInfo(entry, folder_size(entry), (entry / KEEP_MARKER).exists(), is_running(entry)))
    return found


def free_bytes(path: Path) -> int:
    """Bytes free for an unprivileged user on ``path``'s file system."""
    st = os.statvfs(path)
    return st.f_bavail * st.f_frsize


def prune_runs(runs_dir: Path, policy: RunsPolicy, current: Optional[Path] = None, dry_run: bool = False,
               log: Optional[Callable[[str], None]] = None) -> list[PrunedRun]:
    """Delete the oldest finished runs of ``runs_dir`` until ``policy`` holds; what was (or would be) pruned.

    ``current`` (the run now starting) is never pruned, nor is a running or a kept run. Each prune is appended
    to ``runs_dir/prune.log`` and said through ``log``.
    """
    runs_dir = Path(runs_dir)
    folders = run_folders(runs_dir)
    current_real = current.resolve() if current is not None else None
    candidates = [f for f in folders if not f.kept and not f.running and f.path.resolve() != current_real]
    total = sum(f.size_bytes for f in folders)
    free = free_bytes(runs_dir) if runs_dir.is_dir() else 0
    pruned: list[PrunedRun] = []
    remaining = len(candidates)
    for folder in candidates:  # oldest first
        reason = None
        if policy.keep is not None and remaining > policy.keep:
            reason = f"more than the newest {policy.keep} runs"
        elif policy.max_total_mb is not None and total > policy.max_total_mb * MB:
            reason = f"runs over {policy.max_total_mb:g} MB in all"
        elif policy.min_free_mb > 0 and free < policy.min_free_mb * MB:
            reason = f"less than {policy.min_free_mb:g} MB free"
        if reason is None:
            break
        if not dry_run:
            shutil.rmtree(folder.path, ignore_errors=True)
            if folder.path.exists():
                continue  # could not be deleted (permissions): left, and the next one tried
            free = free_bytes(runs_dir)
        else:
            free += folder.size_bytes
        total -= folder.size_bytes
        remaining -= 1
        done = PrunedRun(folder.path.name, folder.size_bytes, reason)
        pruned.append(done)
        if not dry_run:
            _log_prune(runs_dir, done)
        if log is not None:
            log(f"{'would prune' if dry_run else 'pruned'} {done.name} ({done.size_bytes / MB:.1f} MB): {reason}")
    return pruned


def _log_prune(runs_dir: Path, done: PrunedRun) -> None:
    try:
        with open(runs_dir / PRUNE_LOG, "a", encoding="utf-8") as f:
            f.write(f"{utc_now().strftime('%Y-%m-%dT%H:%M:%SZ')}  pruned {done.name}  "
                    f"{done.size_bytes / MB:.1f} MB  {done.reason}\n")
    except OSError:
        pass  # a disk too full for the log line: the prune itself is what frees it


def mark_kept(folder: Path, keep: bool = True, why: str = "") -> None:
    """Mark a run folder as kept (never pruned), or take the mark away."""
    marker = folder / KEEP_MARKER
    if keep:
        marker.write_text((why + "\n") if why else "", encoding="utf-8")
    elif marker.exists():
        marker.unlink()
