"""Editing YAML a person wrote, with ruamel.yaml's round trip: what is not edited stays as it was, byte for byte.

Comments, key order, blank lines, quotes and flow style all survive: the text is loaded in round-trip mode and
dumped again with the indentation the file itself uses (found by trying the usual ones until the unchanged text
comes back byte for byte). A file no single indentation writes back (mixed styles) gets the changed lines patched
into its own text, indented as their siblings are. Used by the studio's map edits (:mod:`beastbt.studio.edits`)
and by live tuning's save to the robot profile (:mod:`beastbt.live.tuning`).
"""

from __future__ import annotations

import io
from typing import Any, Optional

from ruamel.yaml import YAML
from ruamel.yaml.comments import CommentedMap
from ruamel.yaml.error import MarkedYAMLError, YAMLError

INDENTS = ((2, 4, 2), (2, 2, 0), (4, 4, 2), (4, 6, 4), (4, 4, 0), (3, 3, 0), (2, 3, 1))
"""(mapping, sequence, offset) indentations tried, the house style (``steps:`` then ``  - drive``) first."""

class EditRefused(Exception):
    """An edit that cannot be made: why, and where in the text (when it is about a place in it)."""

    def __init__(self, message: str, line: Optional[int] = None, column: Optional[int] = None) -> None:
        super().__init__(message)
        self.line = line
        self.column = column

    def where(self) -> dict:
        """``{line, column}`` when known (for the 400 answer)."""
        return {} if self.line is None else {"line": self.line, "column": self.column or 1}


def _yaml(indent: tuple[int, int, int]) -> YAML:
    y = YAML(typ="rt")
    y.preserve_quotes = True
    y.width = 4096  # never fold a long line the author wrote on one
    y.indent(mapping=indent[0], sequence=indent[1], offset=indent[2])
    return y


def _dump(y: YAML, data: Any) -> str:
    out = io.StringIO()
    y.dump(data, out)
    return out.getvalue()


def _explicit_start(text: str) -> bool:
    """Whether the document starts with ``---`` (after comments and blank lines): ruamel drops it unless told."""
    for line in text.splitlines():
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            return stripped.startswith("---")
    return False


def load_round_trip(text: str) -> tuple[YAML, Any, bool]:
    """(the YAML object that writes this text back closest to unchanged, its data, whether byte for byte);
    raises EditRefused when it is not YAML or not a mapping."""
    best: Optional[tuple[int, YAML, Any]] = None
    for indent in INDENTS:
        y = _yaml(indent)
        y.explicit_start = _explicit_start(text)
        try:
            data = y.load(text)
        except MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            raise EditRefused(f"the text is not valid YAML, so the map cannot change it: {exc.problem or exc}",
                              mark.line + 1 if mark else None, mark.column + 1 if mark else None) from None
        except YAMLError as exc:
            raise EditRefused(f"the text is not valid YAML, so the map cannot change it: {exc}") from None
        if not isinstance(data, CommentedMap):
            raise EditRefused("the map edits a mission: the text must be a mapping with 'mission:' and 'steps:'", 1, 1)
        again = _dump(y, data)
        if again == text:
            return y, data, True
        differing = sum(a != b for a, b in zip(again.splitlines(), text.splitlines())) + abs(
            len(again.splitlines()) - len(text.splitlines()))
        if best is None or differing < best[0]:
            best = (differing, y, data)
    assert best is not None
    return best[1], best[2], False


def _prefix(line: str) -> tuple[str, str]:
    """(indentation with any ``- `` item marks, the rest) of a line."""
    i = 0
    while i < len(line) and (line[i] == " " or (line[i] == "-" and line[i + 1:i + 2] in (" ", ""))):
        i += 1
    return line[:i], line[i:]


def _indent_like(new_lines: list[str], dumped_neighbour: str, original_neighbour: str) -> list[str]:
    """Lines the dumper wrote beside ``dumped_neighbour``, re-indented as the file writes that neighbour.

    A sibling (the same prefix as the neighbour in the dump) gets the file's prefix; deeper lines keep their
    depth relative to the first line (any consistent indentation inside a new block is valid YAML).
    """
    dumped_prefix, _ = _prefix(dumped_neighbour)
    original_prefix, _ = _prefix(original_neighbour)
    if not new_lines:
        return new_lines
    first_prefix, _ = _prefix(new_lines[0])
    if first_prefix == dumped_prefix:
        target = original_prefix
    else:  # not a sibling (a first entry, a new key): shift by the neighbour's indentation difference
        shift = (len(original_prefix) - len(original_prefix.lstrip(" "))) - \
            (len(dumped_prefix) - len(dumped_prefix.lstrip(" ")))
        target = " " * max(0, len(first_prefix) - len(first_prefix.lstrip(" ")) + shift) + first_prefix.lstrip(" ")
    first_indent = len(first_prefix) - len(first_prefix.lstrip(" "))
    target_indent = len(target) - len(target.lstrip(" "))
    out = []
    for line in new_lines:
        if line is new_lines[0]:
            out.append(target + _prefix(line)[1])
            continue
        indent = len(line) - len(line.lstrip(" "))
        out.append(" " * max(0, target_indent + indent - first_indent) + line.lstrip(" ")
                   if indent >= first_indent else line)
    return out


def _entry_line(lines: list[str], mapped: dict[int, int], start: int, step: int) -> Optional[int]:
    """The nearest line from ``start`` (going by ``step``) that is an entry (not blank, not a comment) and is
    found in the original; None when there is none."""
    k = start
    while 0 <= k < len(lines):
        text = lines[k].strip()
        if k in mapped and text and not text.startswith("#"):
            return k
        k += step
    return None


def _sibling(lines: list[str], mapped: dict[int, int], at: int, prefix: str) -> Optional[int]:
    """The nearest entry line around ``at`` written with ``prefix`` (a sibling of a line inserted there) before
    reaching its parent (a line indented less), found in the original; None when there is none."""
    depth = len(prefix) - len(prefix.lstrip(" "))
    for start, step in ((at - 1, -1), (at, 1)):
        k = start
        while 0 <= k < len(lines):
            text = lines[k].strip()
            if text and not text.startswith("#"):
                here = _prefix(lines[k])[0]
                if here == prefix and k in mapped:
                    return k
                if len(here) - len(here.lstrip(" ")) < depth:
                    break
            k += step
    return None


def _patched(original: str, baseline: str, edited: str) -> Optional[str]:
    """``original`` with the change between ``baseline`` (the dump of the unchanged data) and ``edited`` (of the
    changed data) made in it, line by line: for a file whose indentation ruamel cannot write back exactly (mixed
    styles), so that the lines the edit does not touch stay as they were. None when a changed line cannot be
    found in the original (then the caller uses the dump)."""
    from difflib import SequenceMatcher
    o = original.splitlines(keepends=True)
    b = baseline.splitlines(keepends=True)
    e = edited.splitlines(keepends=True)
    strip = [" ".join(_prefix(line)[1].split()) for line in b]  # comments' columns may differ
    o_strip = [" ".join(_prefix(line)[1].split()) for line in o]
    to_o: dict[int, int] = {}
    for tag, i1, i2, j1, j2 in SequenceMatcher(None, strip, o_strip, autojunk=False).get_opcodes():
        if tag == "equal":
            to_o.update({i1 + k: j1 + k for k in range(i2 - i1)})
    out = list(o)
    for tag, i1, i2, j1, j2 in reversed(SequenceMatcher(None, b, e, autojunk=False).get_opcodes()):
        if tag == "equal":
            continue
        new = e[j1:j2]
        if tag in ("replace", "delete"):
            if not all(k in to_o for k in range(i1, i2)):
                return None
            start, end = to_o[i1], to_o[i2 - 1] + 1
            neighbour = (b[i1], o[start])
            if tag == "replace" and len(new) == i2 - i1:  # a line changed in place: keep the file's prefix
                new = [_prefix(o[start + k])[0] + _prefix(line)[1] for k, line in enumerate(new)]
            else:
                new = _indent_like(new, *neighbour)
            out[start:end] = new
        else:  # insert before b[i1], indented as the nearest entry line around it is in the file
            if i1 > 0 and i1 - 1 in to_o:
                at = to_o[i1 - 1] + 1
            elif i1 < len(b) and i1 in to_o:
                at = to_o[i1]
            else:
                return None
            near = _sibling(b, to_o, i1, _prefix(new[0])[0]) if new else None
            near = near if near is not None else _entry_line(b, to_o, i1 - 1, -1)
            near = near if near is not None else _entry_line(b, to_o, i1, 1)
            if near is None:
                return None
            neighbour = (b[near], o[to_o[near]])
            # lines the dump hangs after an entry (its trailing comments) stay before what is inserted
            while at < len(out) and i1 < len(b) and i1 in to_o and at < to_o[i1]:
                at += 1
            out[at:at] = _indent_like(new, *neighbour)
    return "".join(out)


dump = _dump
patched = _patched

__all__ = ["EditRefused", "INDENTS", "load_round_trip", "dump", "patched"]
