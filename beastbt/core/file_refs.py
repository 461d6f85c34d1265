"""Where the files a mission, a world or a request names may be read from, and reading them within bounds.

One policy, :class:`FileRefs`, decides where a named file may be and reads it:

* on the command line (:meth:`FileRefs.anywhere`) a path is taken as written, relative to the folder
  of the file that names it, anywhere on disk: the user owns their disk;
* in the studio (its FOLDER), and on a robot that receives a mission (its mission folder, or the
  folder a sent zip was unpacked into), :meth:`FileRefs.inside` keeps every path inside that folder:
  an absolute path, a ``..`` that climbs out, or a link that leads out is refused.

In every mode a bare name (``world: campus``, ``map: office``: no folder, no suffix) is looked up as
``NAME.yaml`` beside the file that names it, then among the shipped files of its kind (the worlds,
robot profiles and maps beastbt ships); only regular files are read (never a device, a pipe, a
socket or a folder), each kind with a byte cap checked on the opened file (``fstat``) and held
while reading. A refusal (:class:`RefusedFile`) names the path as it was written and says why and
what to do; it never quotes the file.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Optional, Union


@dataclass(frozen=True)
class FileKind:
    """What a named file is: how messages call it, its byte cap, and the shipped folder its bare names look in."""

    what: str
    """How messages name it: ``world file``, ``map image``..."""
    max_bytes: int
    """The largest such file read (bytes)."""
    shipped: Optional[str] = None
    """The folder of shipped files a bare name is looked up in (``worlds``, ``robots``, ``maps``), or None."""
    too_big_hint: Optional[str] = None
    """What to do with a file over the cap (a generic hint when None)."""


# The caps fit what each kind holds, hundreds of times over, and keep what reading one costs bounded: YAML with
# positions takes about 100 times its size in memory to read (1 MB: about 100 MB), GPX and KML some 50 times.
MISSION = FileKind("mission", 2 << 20)
"""A mission YAML: a few kB (4,000 places are 120 kB); as large as the studio edits (2 MB)."""
WORLD = FileKind("world file", 1 << 20, "worlds")
"""A simulated world: walls, obstacles and floor lines; the shipped ones are 2 kB."""
ROBOT = FileKind("robot profile", 256 << 10, "robots")
"""A robot profile: 4 kB at most among the shipped ones."""
MAP = FileKind("map file", 64 << 10, "maps")
"""A ``map_server`` YAML: a dozen lines naming its image."""
MAP_IMAGE = FileKind("map image", 64 << 20)
"""A map's PGM or PNG: 4,000 x 4,000 pixels (16 MB as a PGM) is a large building at 5 cm."""
ROUTE = FileKind("route file", 16 << 20, None, "thin it to at most 10,000 points (GPSBabel: gpsbabel -x simplify,"
                                              "count=10000), or split it")
"""A GPX, KML, GeoJSON, .plan or .waypoints file (route, places or fence): read streaming, its points counted
(at most 10,000: :mod:`beastbt.mission.geo_files`), so its cap is that of the parser's (16 MB)."""
PLACES = FileKind("places file", 512 << 10)
"""A places YAML on a map (``places: {file: ...}``): some 10,000 places."""
JOYSTICK = FileKind("joystick script", 8 << 20, None, "a joystick script holds at most 10,000 events: split it")
"""A scripted joystick (``--joystick FILE``): its events are counted by libyaml's parser before anything is built
(at most 10,000: :mod:`beastbt.sim.joystick_limits`), so its cap is that module's (8 MB)."""
YAML_MAX_BYTES = max(MISSION.max_bytes, WORLD.max_bytes, ROBOT.max_bytes, JOYSTICK.max_bytes)
"""Any YAML file beastbt reads is at most this big (the largest YAML kind's cap)."""
YAML_FILE = FileKind("YAML file", YAML_MAX_BYTES)
"""Any YAML file, as :func:`beastbt.core.yaml_source.load_yaml` reads it (its kind's own cap was checked first)."""


class RefusedFile(Exception):
    """A named file that is not read: ``message`` names the path as written, ``hint`` what to do instead."""

    def __init__(self, message: str, hint: str) -> None:
        super().__init__(message)
        self.message = message
        self.hint = hint


def shipped_names(kind: FileKind) -> list[str]:
    """The bare names of the shipped files of ``kind`` (``campus``, ``corridor``...), sorted; [] if none."""
    folder = _shipped_folder(kind)
    if folder is None:
        return []
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def _shipped_folder(kind: FileKind) -> Optional[Path]:
    if kind.shipped is None:
        return None
    from beastbt.core.resources import data_dir
    try:
        folder = Path(str(data_dir(kind.shipped)))
    except (ModuleNotFoundError, TypeError):
        return None
    return folder if folder.is_dir() else None


def is_bare_name(written: str) -> bool:
    """Whether ``written`` is a name (``campus``) rather than a path (``worlds/campus.yaml``, ``campus.yaml``)."""
    return bool(written) and "/" not in written and "\\" not in written and "." not in written


@dataclass(frozen=True)
class FileRefs:
    """Where named files may be read from (see the module docstring): ``root`` None reads anywhere (the command
    line); else only inside ``root``, a real folder, which messages call ``where`` (``the studio's folder``)."""

    root: Optional[Path] = None
    where: str = "the command line"
    relative_from: str = "the folder of the file that names it"
    """Where a relative path starts, as hints say it (a mission sent to a robot as YAML: its mission folder)."""

    @classmethod
    def anywhere(cls) -> "FileRefs":
        """The command line's policy: paths as written, regular files only, each kind's byte cap."""
        return cls()

    @classmethod
    def inside(cls, root: Union[str, Path], where: str,
               relative_from: str = "the folder of the file that names it") -> "FileRefs":
        """Only files inside ``root`` (after links), or shipped ones by bare name; ``where`` names the folder,
        ``relative_from`` where relative paths start."""
        return cls(Path(os.path.realpath(root)), where, relative_from)

    @property
    def confined(self) -> bool:
        """Whether paths must stay inside :attr:`root`."""
        return self.root is not None

    # -- finding ------------------------------------------------------------------------------
    def locate(self, written: object, base: Union[str, Path], kind: FileKind) -> Path:
        """The file that ``written`` (as a mission or a world wrote it) names, from a file in folder ``base``:
        a bare name beside that file, then among the shipped ones; else a path. Checked as :meth:`check` does.
        Raises :class:`RefusedFile`."""
        if not isinstance(written, str) or not written.strip():
            raise RefusedFile(f"the {kind.what} must be named by a path or a name", self._path_hint(kind))
        if "\x00" in written or len(written) > 1024:
            raise RefusedFile(f"'{_shown(written)}' is not a file name", self._path_hint(kind))
        if written.rstrip().endswith(("/", "/.", "/..")) or written.strip() in (".", ".."):
            # 'x.yaml/.' names the folder x.yaml (pathlib would quietly drop the '.')
            raise RefusedFile(f"the {kind.what} '{_shown(written)}' names a folder, not a file", "name a file in it")
        base = Path(base)
        if is_bare_name(written) and kind.shipped is not None:
            return self._by_name(written, base, kind)
        pure = PurePosixPath(written)
        target = Path(written) if pure.is_absolute() else base / written
        if self.root is not None:
            if pure.is_absolute():
                raise RefusedFile(f"the {kind.what} '{_shown(written)}' is an absolute path: only files inside "
                                  f"{self.where} are read", self._path_hint(kind))
            real = Path(os.path.realpath(target))
            if not _inside(real, self.root):
                how = "climbs out of" if ".." in pure.parts else "is a link that leads out of"
                raise RefusedFile(f"the {kind.what} '{_shown(written)}' {how} {self.where}: only files inside it "
                                  f"are read", self._path_hint(kind))
            target = real
        elif not pure.is_absolute():
            target = target.resolve()  # as the command line always showed it: absolute, without '..'
        try:
            self.check(target, kind, written)
        except RefusedFile as exc:
            if "does not exist" not in exc.message:
                raise
            raise RefusedFile(exc.message, f"check the name; a relative path is read from {self.relative_from}"
                                           + self._shipped_hint(kind)) from None
        return target

    def _by_name(self, written: str, base: Path, kind: FileKind) -> Path:
        beside = base / f"{written}.yaml"
        if os.path.lexists(beside) and (self.root is None or _inside(Path(os.path.realpath(beside)), self.root)):
            self.check(beside, kind, written)
            return beside
        folder = _shipped_folder(kind)
        if folder is not None and (folder / f"{written}.yaml").is_file():
            found = folder / f"{written}.yaml"
            self.check(found, kind, written)
            return found
        from beastbt.core.errors import did_you_mean
        names = shipped_names(kind)
        shipped = f"the shipped ones are {', '.join(names)}" if names else f"beastbt ships no {kind.what}"
        raise RefusedFile(f"no {kind.what} called '{written}' beside this file nor among the shipped "
                          f"ones{did_you_mean(written, names)}",
                          f"{shipped}; or write the file's path ({written}.yaml beside this file)")

    def _shipped_hint(self, kind: FileKind) -> str:
        names = shipped_names(kind)
        return f"; or name a shipped one: {', '.join(names)}" if names else ""

    def _path_hint(self, kind: FileKind) -> str:
        if self.root is None:
            return f"a relative path is read from {self.relative_from}{self._shipped_hint(kind)}"
        return f"give a path relative to {self.relative_from}, inside {self.where}{self._shipped_hint(kind)}"

    # -- reading ------------------------------------------------------------------------------
    def check(self, path: Union[str, Path], kind: FileKind, written: Optional[str] = None) -> None:
        """Open ``path`` and check it is a regular file within ``kind``'s cap (RefusedFile if not); read nothing."""
        fd = _open_regular(path, kind, written if written is not None else str(path))
        os.close(fd)

    def read_bytes(self, path: Union[str, Path], kind: FileKind, written: Optional[str] = None) -> bytes:
        """The bytes of the regular file at ``path``, at most ``kind.max_bytes`` (RefusedFile otherwise)."""
        return read_capped(path, kind, written)


def read_capped(path: Union[str, Path], kind: FileKind, written: Optional[str] = None) -> bytes:
    """The bytes of the regular file at ``path``: opened without blocking (a pipe cannot hang it), checked with
    ``fstat`` (regular, at most ``kind.max_bytes``), read no further than the cap. RefusedFile otherwise, naming
    the file as ``written`` (default: ``path``)."""
    shown = written if written is not None else str(path)
    fd = _open_regular(path, kind, shown)
    try:
        chunks = []
        left = kind.max_bytes + 1
        while left > 0:
            chunk = os.read(fd, min(left, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
    except OSError as exc:
        from beastbt.core.errors import plain_reason
        raise RefusedFile(f"cannot read the {kind.what} '{_shown(shown)}': {plain_reason(exc)}",
                          "check the file and its permissions") from None
    finally:
        os.close(fd)
    data = b"".join(chunks)
    if len(data) > kind.max_bytes:  # it grew after fstat
        raise _too_big(kind, shown, len(data))
    return data


def _open_regular(path: Union[str, Path], kind: FileKind, shown: str) -> int:
    """A descriptor of the regular file at ``path`` within ``kind``'s cap (the caller closes it)."""
    from beastbt.core.errors import plain_reason
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    text = str(path)
    if text.endswith(("/", "/.")) or text in (".", ".."):
        raise RefusedFile(f"the {kind.what} '{_shown(shown)}': this is a folder, not a file", "name a file in it")
    try:
        # a device is not even opened (opening some has effects: a watchdog starts, a tape rewinds); fstat below
        # checks the file actually opened, should it have been swapped in between
        before = os.stat(text)
        if not stat.S_ISREG(before.st_mode) and not stat.S_ISDIR(before.st_mode):
            raise RefusedFile(f"the {kind.what} '{_shown(shown)}' is not a regular file (a device, a pipe or a "
                              f"socket): only files are read", f"name a {kind.what} saved on disk")
        fd = os.open(text, flags)
    except FileNotFoundError:
        raise RefusedFile(f"the {kind.what} '{_shown(shown)}' does not exist",
                          "check the name; a relative path is read from the folder of the file that names it"
                          ) from None
    except IsADirectoryError:
        raise RefusedFile(f"the {kind.what} '{_shown(shown)}': this is a folder, not a file",
                          "name a file in it") from None
    except OSError as exc:
        raise RefusedFile(f"cannot open the {kind.what} '{_shown(shown)}': {plain_reason(exc)}",
                          "check the path and the file's permissions") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise RefusedFile(f"the {kind.what} '{_shown(shown)}': this is a folder, not a file",
                              "name a file in it")
        if not stat.S_ISREG(info.st_mode):
            raise RefusedFile(f"the {kind.what} '{_shown(shown)}' is not a regular file (a device, a pipe or a "
                              f"socket): only files are read", f"name a {kind.what} saved on disk")
        if info.st_size > kind.max_bytes:
            raise _too_big(kind, shown, info.st_size)
    except BaseException:
        os.close(fd)
        raise
    return fd


def _too_big(kind: FileKind, shown: str, size: int) -> RefusedFile:
    return RefusedFile(f"the {kind.what} '{_shown(shown)}' is {_megabytes(size)}: a {kind.what} is read up to "
                       f"{_megabytes(kind.max_bytes)}", kind.too_big_hint or f"a {kind.what} is read whole: split "
                                                                             f"it, or make it coarser")


def _megabytes(size: int) -> str:
    """A size for a person: MB (2^20 bytes) with one decimal where it matters, kB below one MB."""
    if size >= 1 << 20:
        mb = size / (1 << 20)
        return f"{mb:,.0f} MB" if mb == int(mb) or mb >= 100 else f"{mb:,.1f} MB"
    return f"{size / 1024:,.0f} kB"


def _inside(path: Path, root: Path) -> bool:
    return path == root or root in path.parents


def _shown(written: str) -> str:
    """A path as written, made safe to print: at most 200 characters, control characters escaped."""
    text = written if len(written) <= 200 else written[:197] + "..."
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


CLI = FileRefs.anywhere()
"""The command line's policy (the default wherever a caller names none)."""

__all__ = ["FileRefs", "FileKind", "RefusedFile", "read_capped", "shipped_names", "is_bare_name", "CLI",
           "YAML_FILE", "MISSION", "WORLD", "ROBOT", "MAP", "MAP_IMAGE", "ROUTE", "PLACES", "JOYSTICK", "YAML_MAX_BYTES"]
