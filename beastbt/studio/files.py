"""The studio's FOLDER: the missions, worlds and robots under it, read and saved by relative path.

Every path is relative to the folder and must stay inside it: an absolute
path, a ``..`` part, or a symlink that leads out is refused
(:class:`FileRefused`, a 4xx); so is a name longer than the disk takes, and a
save into a hidden file or folder (``.git/...``). A file's version is the
SHA-256 of its bytes, so a save can tell whether the file changed on disk since
it was read; a save keeps the previous content beside the file as ``FILE.bak``.
A save the disk refuses is a 507 when the disk is full, a 403 when it may not be
written, never a 500.
"""

from __future__ import annotations

import errno
import hashlib
import os
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Optional


TEXT_SUFFIXES = (".yaml", ".yml")
"""What the studio lists by kind, opens and saves: YAML files."""
OTHER_SUFFIXES = (".gpx", ".geojson", ".kml", ".csv")
"""Listed as ``other`` (a mission's geo files), opened read-only-ish: saved like the rest when asked."""
SKIPPED_DIRS = frozenset({"node_modules", "__pycache__", "runs", "site-packages", "venv"})
"""Folders not walked (a run folder holds recordings, not missions)."""
MAX_FILES = 2000
"""At most this many files are listed: a FOLDER of a whole disk must not stall the page."""
MAX_BYTES = 2_000_000
"""A file the studio opens or saves is at most this big (bytes): missions are a few kB."""
MAX_NAME_BYTES = 255
"""The longest name of one file or folder (bytes of UTF-8): what Linux's file systems take (NAME_MAX)."""
MAX_PATH_BYTES = 1024
"""The longest relative path the studio takes (bytes of UTF-8): deeper than any folder of missions."""
FULL_DISK_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})
"""An OS error that means the disk (or the user's quota) is full: answered 507."""
KINDS = {"mission": "mission", "steps": "mission", "world": "world", "robot": "robot", "test": "test"}
"""First key of a YAML mapping -> the kind of file (as ``beastbt validate`` tells them apart)."""


class FileRefused(Exception):
    """A request the folder cannot serve: ``status`` (400, 403, 404, 409, 413, 415, 507) and a message."""

    def __init__(self, status: int, message: str, disk_text: Optional[str] = None, exists: bool = True) -> None:
        super().__init__(message)
        self.status = status
        self.disk_text = disk_text
        """On a 409: the text on disk now (None when the file is gone)."""
        self.exists = exists


def version_of(data: bytes) -> str:
    """A file's version: the hex SHA-256 of its bytes."""
    return hashlib.sha256(data).hexdigest()


def kind_of(text: str) -> str:
    """``mission``, ``world``, ``robot``, ``test`` (a mission test) or ``other`` from the first key of a YAML text (cheaply: its first key
    line)."""
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith("#") or stripped == "---":
            continue
        if line[0] in " \t-":
            return "other"
        key = stripped.split(":", 1)[0].strip().strip("'\"")
        return KINDS.get(key, "other")
    return "other"


@dataclass
class StudioFolder:
    """The folder the studio serves (see the module docstring)."""

    root: Path

    def __post_init__(self) -> None:
        self.root = Path(os.path.realpath(self.root))
        self._lock = threading.Lock()

    # -- paths --------------------------------------------------------------------------
    def resolve(self, rel: str, must_exist: bool = True) -> Path:
        """The real path of ``rel`` inside the folder; raises :class:`FileRefused` for one that leads out."""
        if not rel or "\x00" in rel or "\\" in rel:
            raise FileRefused(400, f"'{rel[:80]}' is not a file path: give a path relative to the studio's folder, "
                                   f"with '/' between folders")
        pure = PurePosixPath(rel)
        if pure.is_absolute() or (len(rel) > 1 and rel[1] == ":"):
            raise FileRefused(403, f"'{rel[:80]}' is an absolute path: the studio serves only files under its folder; "
                                   f"give a path relative to it")
        if any(part == ".." for part in pure.parts):
            raise FileRefused(403, f"'{rel[:80]}' leads out of the studio's folder ('..'): only files under it are "
                                   f"served")
        longest = max(pure.parts, key=lambda part: len(part.encode("utf-8")), default="")
        if len(longest.encode("utf-8")) > MAX_NAME_BYTES:
            raise FileRefused(400, f"'{longest[:40]}...' is a name of {len(longest.encode('utf-8'))} bytes: a file or "
                                   f"folder name is at most {MAX_NAME_BYTES}; choose a shorter one")
        if len(rel.encode("utf-8")) > MAX_PATH_BYTES:
            raise FileRefused(400, f"'{rel[:40]}...' is a path of {len(rel.encode('utf-8'))} bytes: the studio takes "
                                   f"paths of at most {MAX_PATH_BYTES}; use fewer or shorter folders")
        target = self.root.joinpath(*pure.parts)
        real = Path(os.path.realpath(target))
        if not _inside(real, self.root):
            raise FileRefused(403, f"'{rel[:80]}' is a link that leads out of the studio's folder: only files under "
                                   f"it are served")
        if must_exist and not real.is_file():
            raise FileRefused(404, f"no file '{rel[:80]}' in the studio's folder")
        return real

    def relative(self, path: Path) -> str:
        """``path`` (inside the folder) as the relative path the API uses."""
        return Path(path).relative_to(self.root).as_posix()

    # -- listing ------------------------------------------------------------------------
    def list(self) -> list[dict]:
        """The YAML (and geo) files under the folder, sorted: ``{path, kind, size, version}`` each."""
        found: list[dict] = []
        for dirpath, dirnames, filenames in os.walk(self.root, followlinks=False):
            dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and d not in SKIPPED_DIRS)
            for name in sorted(filenames):
                if name.startswith(".") or not name.lower().endswith(TEXT_SUFFIXES + OTHER_SUFFIXES):
                    continue
                full = Path(dirpath, name)
                try:
                    real = Path(os.path.realpath(full))
                    if not _inside(real, self.root) or not real.is_file():
                        continue  # a link that leads out is not shown (and would be refused)
                    size = real.stat().st_size
                    data = real.read_bytes() if size <= MAX_BYTES else b""
                except OSError:
                    continue
                kind = "other"
                if name.lower().endswith(TEXT_SUFFIXES):
                    kind = kind_of(data[:4096].decode("utf-8", errors="replace"))
                found.append({"path": self.relative(full), "kind": kind, "size": size, "version": version_of(data)})
                if len(found) >= MAX_FILES:
                    return found
        return found

    # -- reading and saving -------------------------------------------------------------------
    def read(self, rel: str) -> dict:
        """``{path, text, version, kind}`` of one file; raises :class:`FileRefused`."""
        real = self.resolve(rel)
        data = _read_bytes(real, rel)
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise FileRefused(415, f"'{rel}' is not UTF-8 text: the studio edits YAML text files") from None
        return {"path": rel, "text": text, "version": version_of(data),
                "kind": kind_of(text) if real.name.lower().endswith(TEXT_SUFFIXES) else "other"}

    def write(self, rel: str, text: str, version: Optional[str]) -> str:
        """Save ``text`` at ``rel`` if the file on disk is still at ``version`` (None: it must not exist yet).

        The previous content is kept as ``FILE.bak``; the new one is written to a temporary file and renamed
        over the old one, so a crash leaves one or the other, never half. Returns the new version; raises
        :class:`FileRefused` (409 with the disk's text when it changed since ``version``).
        """
        if not rel.lower().endswith(TEXT_SUFFIXES + OTHER_SUFFIXES):
            raise FileRefused(400, f"'{rel[:80]}': the studio saves YAML files ({', '.join(TEXT_SUFFIXES)}) and "
                                   f"geo files ({', '.join(OTHER_SUFFIXES)}) only")
        if any(part.startswith(".") for part in PurePosixPath(rel).parts):
            # hidden files and folders are not listed: .git/config and the like are not the studio's to write
            raise FileRefused(403, f"'{rel[:80]}' is hidden (a name that starts with '.'): the studio does not save "
                                   f"into hidden files or folders; choose a name without a leading '.'")
        data = text.encode("utf-8")
        if len(data) > MAX_BYTES:
            raise FileRefused(413, f"the text is over {MAX_BYTES} bytes: a mission is a few kB")
        real = self.resolve(rel, must_exist=False)
        try:
            return self._write(real, rel, data, version)
        except OSError as exc:
            raise refusal_of(exc, f"'{rel[:80]}' was not saved") from None

    def _write(self, real: Path, rel: str, data: bytes, version: Optional[str]) -> str:
        with self._lock:
            exists = real.exists()
            if exists and not real.is_file():
                raise FileRefused(400, f"'{rel}' is a folder, not a file")
            if version is None:
                if exists:
                    disk = _read_bytes(real, rel)
                    raise FileRefused(409, f"'{rel}' exists already: open it, or save under another name",
                                      disk.decode("utf-8", errors="replace"))
                if not _inside(Path(os.path.realpath(real.parent)), self.root):
                    raise FileRefused(403, f"'{rel}': its folder leads out of the studio's folder")
                real.parent.mkdir(parents=True, exist_ok=True)
            else:
                if not exists:
                    raise FileRefused(409, f"'{rel}' was deleted or moved on disk since it was opened; save it under "
                                           f"a name (the text is still in the editor)", None, exists=False)
                disk = _read_bytes(real, rel)
                if version_of(disk) != version:
                    raise FileRefused(409, f"'{rel}' changed on disk since it was opened: nothing was saved; compare "
                                           f"the two and save again", disk.decode("utf-8", errors="replace"))
                _atomic_write(real.with_name(real.name + ".bak"), disk)
            _atomic_write(real, data)
        return version_of(data)


def refusal_of(exc: OSError, what: str) -> FileRefused:
    """The answer to an OS error while writing: 507 for a full disk, 400 for a name too long, 403 otherwise (a
    read-only disk, no permission), each saying what happened and what to do."""
    from beastbt.core.errors import plain_reason
    if exc.errno in FULL_DISK_ERRNOS:
        return FileRefused(507, f"{what}: the disk is full; free some space and try again (the text is still in "
                                f"the editor)")
    if exc.errno == errno.ENAMETOOLONG:
        return FileRefused(400, f"{what}: the name is too long for the disk; choose a shorter one")
    return FileRefused(403, f"{what}: {plain_reason(exc)}")


def _inside(path: Path, root: Path) -> bool:
    return path == root or root in path.parents


def _read_bytes(real: Path, rel: str) -> bytes:
    try:
        if real.stat().st_size > MAX_BYTES:
            raise FileRefused(413, f"'{rel}' is over {MAX_BYTES} bytes: the studio edits missions, a few kB each")
        return real.read_bytes()
    except FileRefused:
        raise
    except OSError as exc:
        from beastbt.core.errors import plain_reason
        raise FileRefused(404 if isinstance(exc, FileNotFoundError) else 403,
                          f"cannot read '{rel}': {plain_reason(exc)}") from None


def _atomic_write(path: Path, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(prefix="." + path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        if path.exists():
            try:
                os.chmod(tmp, path.stat().st_mode & 0o777)
            except OSError:
                pass
        else:
            os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


__all__ = ["FileRefused", "StudioFolder", "kind_of", "refusal_of", "version_of"]
