"""Checks of the files and folders a command will write, made before anything starts."""

from __future__ import annotations

from pathlib import Path
from typing import Optional


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


__all__ = ["output_file_problem", "output_folder_problem"]
