"""How large a joystick script (``--joystick FILE``) may be, checked before its YAML is built into values.

A script of 2 million events (63 MB) grew ``beastbt validate`` to 3.9 GB and
``run`` to 800 MB (issue 38): building every event with its position costs
some sixty times the file's bytes. So the file's size is checked with ``stat``
before it is read, and its events and values are counted by libyaml's parser
(which builds nothing and keeps its own stack) before the document is
composed; the first one over a bound is an error at its line and column.

This module imports only PyYAML: ``beastbt validate`` uses it on every file
that is a list at its top level, before it knows it holds a joystick script.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Optional, Union

import yaml

from beastbt.core.errors import Position, Problem

MAX_SCRIPT_BYTES = 8 << 20
"""The largest joystick script read, in bytes (8 MiB)."""
MAX_SCRIPT_EVENTS = 10_000
"""The most events a joystick script may hold: a scripted test presses and moves some dozens of times; a
recorded stick at 20 Hz gives 10,000 events in over 8 minutes."""
MAX_SCRIPT_VALUES = 20 * MAX_SCRIPT_EVENTS
"""The most YAML values (lists, mappings and scalars, keys included) a joystick script may hold: an event is a
mapping of at most five keys and their values."""
SCRIPT_HINT = ("a joystick script is a short list of timed events ({at: 2 s, press: enable}); for a long drive, "
               "split it, or drive with the mission's steps")
"""The hint of an oversized script."""
_SNIFF_BYTES = 4096
"""How much of a file is read to tell whether it is a list at its top level."""


def looks_like_a_list(head: str) -> bool:
    """Whether a YAML text whose start is ``head`` is a list at its top level (its first content line starts with
    ``-`` or ``[``): a joystick script, or a mission written with a ``-`` too many."""
    for line in head.splitlines():
        stripped = line.strip()
        if stripped and not stripped.startswith("#") and stripped != "---" and not stripped.startswith("%"):
            return stripped.startswith(("- ", "[")) or stripped == "-"
    return False


def script_size_problem(path: Union[str, Path], display_name: Optional[str] = None) -> Optional[Problem]:
    """The problem of a joystick script file beyond :data:`MAX_SCRIPT_BYTES`, or holding more than
    :data:`MAX_SCRIPT_EVENTS` events or :data:`MAX_SCRIPT_VALUES` values; None when it is within them or cannot be
    read (the loader says why). Only the file's size is read for the first check, and the text is parsed
    without being composed for the others."""
    name = display_name or str(path)
    too_big = file_size_problem(path, name)
    if too_big is not None:
        return too_big
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    return text_size_problem(text, name)


def file_size_problem(path: Union[str, Path], name: str) -> Optional[Problem]:
    """The problem of a joystick script file over :data:`MAX_SCRIPT_BYTES` (from ``stat``, nothing read), else
    None (also for what is no regular file: the loader says why)."""
    try:
        info = os.stat(path)
    except OSError:
        return None
    if not stat.S_ISREG(info.st_mode) or info.st_size <= MAX_SCRIPT_BYTES:
        return None
    return Problem(name, Position(1, 1), f"the joystick script is {info.st_size / (1 << 20):,.1f} MB: a joystick "
                                         f"script is read up to {MAX_SCRIPT_BYTES >> 20} MB", SCRIPT_HINT)


def text_size_problem(text: str, name: str) -> Optional[Problem]:
    """:func:`script_size_problem` for a script's text (its events and values counted by libyaml's parser)."""
    if len(text.encode("utf-8", errors="replace")) > MAX_SCRIPT_BYTES:
        return Problem(name, Position(1, 1), f"the joystick script is over {MAX_SCRIPT_BYTES >> 20} MB: a joystick "
                                             f"script is read up to {MAX_SCRIPT_BYTES >> 20} MB", SCRIPT_HINT)
    loader = yaml.CSafeLoader if getattr(yaml, "__with_libyaml__", False) else yaml.SafeLoader
    depth = events = values = 0
    try:
        for event in yaml.parse(text, Loader=loader):
            if isinstance(event, (yaml.ScalarEvent, yaml.AliasEvent, yaml.CollectionStartEvent)):
                values += 1
                if depth == 1:
                    events += 1
                    if events > MAX_SCRIPT_EVENTS:
                        return _at(name, event, f"more than {MAX_SCRIPT_EVENTS:,} events: a joystick script holds "
                                                f"at most {MAX_SCRIPT_EVENTS:,}")
                if values > MAX_SCRIPT_VALUES:
                    return _at(name, event, f"more than {MAX_SCRIPT_VALUES:,} values: a joystick script holds at "
                                            f"most {MAX_SCRIPT_VALUES:,} ({MAX_SCRIPT_EVENTS:,} events)")
            if isinstance(event, yaml.CollectionStartEvent):
                depth += 1
            elif isinstance(event, yaml.CollectionEndEvent):
                depth -= 1
    except yaml.YAMLError:
        return None  # the YAML loader says where and why, as for any file
    return None


def _at(name: str, event: yaml.Event, message: str) -> Problem:
    mark = event.start_mark
    return Problem(name, Position(mark.line + 1, mark.column + 1), message, SCRIPT_HINT)


def list_file_problem(path: Union[str, Path], display_name: Optional[str] = None) -> Optional[Problem]:
    """:func:`script_size_problem` for a file that is a list at its top level (sniffed from its first
    :data:`_SNIFF_BYTES` bytes), None for any other file: what ``beastbt validate`` asks before reading a file
    whole."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return None  # not opened: opening a pipe would wait for a writer (the loader says what it is)
        with open(path, "rb") as f:
            head = f.read(_SNIFF_BYTES).decode("utf-8", errors="replace")
    except OSError:
        return None
    return script_size_problem(path, display_name) if looks_like_a_list(head) else None


__all__ = ["MAX_SCRIPT_BYTES", "MAX_SCRIPT_EVENTS", "MAX_SCRIPT_VALUES", "script_size_problem", "file_size_problem", "text_size_problem",
           "list_file_problem", "looks_like_a_list"]
