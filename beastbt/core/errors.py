"""Problems found in a user's file, each with a position, and how they are reported.

Every problem a user can cause is a :class:`Problem`: file, line and column
(1-based), what is wrong, what was expected and a hint. They are printed as
``FILE:LINE:COLUMN: error: ...`` and collected so that all the problems of a
file are reported in one run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Optional


@dataclass(frozen=True, order=True)
class Position:
    """A place in a file: 1-based line and column."""

    line: int = 1
    column: int = 1


@dataclass(frozen=True)
class Problem:
    """One error (or warning) in a user's file."""

    file: str
    position: Position
    message: str
    hint: Optional[str] = None
    severity: str = "error"
    """``error`` (nothing runs) or ``warning`` (it runs, unless ``--strict``)."""

    def format(self) -> str:
        """Render as ``FILE:LINE:COLUMN: error: message`` (or ``warning:``) plus an indented hint line; a problem with a
        command-line option (its ``file`` is the option, ``--console``) as ``beastbt: --console: error: message``."""
        if self.file.startswith("--"):
            # A command-line option has no lines: 'beastbt run: --console: error: ...', not '--console:1:1:'.
            text = f"beastbt: {self.file}: {self.severity}: {self.message}"
        else:
            text = f"{self.file}:{self.position.line}:{self.position.column}: {self.severity}: {self.message}"
        if self.hint:
            text += f"\n    hint: {self.hint}"
        return text


@dataclass
class InvalidInput(Exception):
    """Raised when a mission, profile or world has problems; carries all of them, sorted."""

    problems: list[Problem] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.problems = sorted(set(self.problems), key=lambda p: (p.file, p.position, p.message))
        super().__init__(self.format())

    def format(self) -> str:
        """All problems, one per line (hints indented below)."""
        return "\n".join(p.format() for p in self.problems)


def warning(problem: Problem) -> Problem:
    """The same problem as a warning."""
    return Problem(problem.file, problem.position, problem.message, problem.hint, "warning")


def plain_reason(exc: BaseException) -> str:
    """Why an OS call failed, in words and without ``[Errno N]``: ``it does not exist``, ``permission denied``..."""
    import errno as _errno
    code = getattr(exc, "errno", None)
    inner = exc.__context__ if code is None else None
    if code is None and isinstance(inner, OSError):
        code = inner.errno
    if code is None:
        text = str(exc)
        for number, word in (("[Errno 2]", _errno.ENOENT), ("[Errno 13]", _errno.EACCES), ("[Errno 16]", _errno.EBUSY),
                             ("[Errno 19]", _errno.ENODEV), ("[Errno 6]", _errno.ENXIO)):
            if number in text:
                code = word
                break
    words = {_errno.ENOENT: "it does not exist", _errno.EACCES: "permission denied",
             _errno.EPERM: "permission denied", _errno.EBUSY: "it is busy (another program has it open)",
             _errno.ENODEV: "no such device", _errno.ENXIO: "no device answers there",
             _errno.EIO: "input/output error (a loose cable?)", _errno.ENOTDIR: "a part of the path is not a folder",
             _errno.EISDIR: "it is a folder"}
    if code in words:
        return words[code]
    text = getattr(exc, "strerror", None) or str(exc)
    import re as _re
    return _re.sub(r"\[Errno \d+\]\s*", "", text).strip() or type(exc).__name__


def value_in_words(value: object) -> str:
    """What a YAML value is, for people: "nothing (an empty value)", "a list", "a mapping", "true/false"...

    Errors never show Python's type names (NoneType, dict): a mission's author writes YAML, not Python.
    """
    if isinstance(value, bool):
        return "true/false"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
    if isinstance(value, (int, float)):
        return f"the number {value}"
    if value is None:
        return "nothing (an empty value)"
    return f"'{value}'"


def closest(word: str, choices: Iterable[str]) -> Optional[str]:
    """The valid word closest to a misspelt ``word``, or None when nothing is close."""
    import difflib  # only when a word is misspelt: it costs every start-up otherwise

    matches = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return matches[0] if matches else None


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` when a close valid word exists, else ``""``."""
    best = closest(word, choices)
    return f"; did you mean '{best}'?" if best else ""
