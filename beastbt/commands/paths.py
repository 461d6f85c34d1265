"""Checks of the files and folders a command will write, made before anything starts."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable, Optional, TypeVar

T = TypeVar("T")


def output_file_problem(option: str, path: Optional[str]) -> Optional[str]:
    """Why ``path`` (given with ``option``) cannot be written, in one sentence with the fix; None when it can."""
    if not path:
        return None
    target = Path(path)
    if target.is_dir():
        return f"{option} {path}: that is a folder; give a file name, e.g. {target / 'out'}"
    folder = target.parent
    if not folder.exists():
        return f"{option} {path}: the folder {folder} does not exist; create it first (mkdir -p {folder})"
    if not folder.is_dir():
        return f"{option} {path}: {folder} is a file, not a folder"
    return None


def output_folder_problem(option: str, path: Optional[str]) -> Optional[str]:
    """Why ``path`` cannot be used as a folder to write into (it is a file, or under one); None when it can."""
    if not path:
        return None
    target = Path(path)
    for part in (target, *target.parents):
        if part.exists():
            if not part.is_dir():
                return f"{option} {path}: {part} is a file, not a folder; choose a folder"
            return None
    return None


def read_run(command: str, run: str, read: Callable[[], T]) -> Optional[T]:
    """``read()`` a recorded run; when it cannot be read, say why on standard error and return None (exit 2).

    A missing folder or file and a recording without what the command needs
    (OSError, ValueError) say so; a file that is not MCAP says it cannot be read.
    """
    from mcap.exceptions import McapError
    try:
        return read()
    except (OSError, ValueError) as exc:
        message = str(exc)
    except McapError as exc:
        message = f"{run}: cannot read the recording ({exc})"
    print(f"beastbt {command}: error: {message}", file=sys.stderr)
    return None


__all__ = ["output_file_problem", "output_folder_problem", "read_run"]
