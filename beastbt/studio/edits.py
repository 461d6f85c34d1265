"""Edits the map makes to a mission's text, with ruamel.yaml's round trip: the rest of the file is kept as it was.

Comments, key order, blank lines, quotes and flow style all survive: the text
is loaded in round-trip mode and dumped again with the indentation the file
itself uses (found by trying the usual ones until the unchanged text comes back
byte for byte). A file no single indentation writes back (mixed styles) gets
the changed lines patched into its own text, indented as their siblings are.
Only the part an edit touches is new. Numbers are rounded:
latitude and longitude to 7 decimals (about 1 cm).
"""

from __future__ import annotations

import io
import string
from typing import Any, Optional

from ruamel.yaml import YAML
from ruamel.yaml.comments import CommentedMap, CommentedSeq
from ruamel.yaml.error import CommentMark, MarkedYAMLError, YAMLError
from ruamel.yaml.tokens import CommentToken

LATLON_DECIMALS = 7
"""Decimals of a latitude or longitude written by an edit (1e-7 deg is about 1 cm)."""
INDENTS = ((2, 4, 2), (2, 2, 0), (4, 4, 2), (4, 6, 4), (4, 4, 0), (3, 3, 0), (2, 3, 1))
"""(mapping, sequence, offset) indentations tried, the house style (``steps:`` then ``  - drive``) first."""
KEY_ORDER = ("mission", "description", "world", "map", "rate", "limits", "places", "fences", "tasks", "steps")
"""Where a new top-level key goes: after the last of these that comes before it and is there."""


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


def _coordinate(edit: dict, key: str, low: float, high: float) -> float:
    value = edit.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
        raise EditRefused(f"'{key}' must be a number from {low:g} to {high:g} (decimal degrees), not {value!r}")
    return round(float(value), LATLON_DECIMALS)


def _name(edit: dict, key: str = "name") -> Optional[str]:
    name = edit.get(key)
    if name is None or name == "":
        return None
    if not isinstance(name, str) or not name.replace("_", "a").replace("-", "a").isalnum() or not name[0].isalpha():
        raise EditRefused(f"'{name}' is not a name: use letters, digits, _ and -, starting with a letter")
    return name


def _is_block(node: Any) -> bool:
    return isinstance(node, (CommentedMap, CommentedSeq)) and len(node) > 0 and not node.fa.flow_style()


def _detach_tail(node: Any) -> Optional[str]:
    """Take the comment lines and blank lines after the last entry of a block ``node`` (what ruamel hangs on the
    deepest last entry), keeping that entry's own end-of-line comment; returns them (None when there are none).

    An entry appended after them then goes right after the last one, and the lines stay where they were: before
    what follows in the file.
    """
    if not _is_block(node):
        return None
    last: Any = list(node.keys())[-1] if isinstance(node, CommentedMap) else len(node) - 1
    slot = node.ca.items.get(last)
    at = 2 if isinstance(node, CommentedMap) else 0
    token = slot[at] if slot and len(slot) > at else None
    rest: Optional[str] = None
    if isinstance(token, CommentToken):
        head, sep, rest = token.value.partition("\n")
        token.value = head + sep
    else:
        rest = _detach_tail(node[last])
    end = getattr(node.ca, "end", None)
    if end:  # the comments at the end of a block list or mapping that ends the document
        rest = (rest or "") + "".join(t.value for t in end if isinstance(t, CommentToken))
        node.ca.end = []
    return rest or None


def _attach_tail(node: Any, key: Any, rest: Optional[str]) -> None:
    """Hang ``rest`` (from :func:`_detach_tail`) after the entry ``key`` of ``node``, the deepest last one inside."""
    if not rest:
        return
    value = node[key]
    if _is_block(value):
        _attach_tail(value, list(value.keys())[-1] if isinstance(value, CommentedMap) else len(value) - 1, rest)
        return
    at = 2 if isinstance(node, CommentedMap) else 0
    slot = node.ca.items.setdefault(key, [None, None, None, None])
    while len(slot) <= at:
        slot.append(None)
    slot[at] = CommentToken("\n" + rest, CommentMark(0), None)


def _append(node: Any, key: Any, value: Any) -> None:
    """Append ``key: value`` to a mapping (``key`` None: ``value`` to a sequence); the lines after its end stay
    after it."""
    rest = _detach_tail(node)
    if isinstance(node, CommentedMap):
        node[key] = value
    else:
        node.append(value)
        key = len(node) - 1
    _attach_tail(node, key, rest)


def _add_entry(data: CommentedMap, top: str, container: Any, key: Any, value: Any) -> None:
    """Add ``key: value`` (``key`` None: ``value`` to a list) to the top-level ``container`` called ``top``; a
    container not in the text yet (a new one, empty) is put in place with it."""
    fresh = data.get(top) is not container
    if fresh or len(container) == 0:
        if len(container) == 0:
            container.fa.set_block_style()  # 'places: {}' grows into a block, one place a line
        if isinstance(container, CommentedMap):
            container[key] = value
        else:
            container.append(value)
        if fresh:
            _put_top(data, top, container)
        return
    _append(container, key, value)


def _flow(mapping: dict) -> CommentedMap:
    m = CommentedMap(mapping)
    m.fa.set_flow_style()
    return m


def _flow_seq(items: list) -> CommentedSeq:
    s = CommentedSeq(items)
    s.fa.set_flow_style()
    return s


def _put_top(data: CommentedMap, key: str, value: Any) -> None:
    """Set the top-level ``key`` to ``value`` (complete): in place when the key is there (``places:`` with nothing
    after it), else inserted at its usual place (:data:`KEY_ORDER`), the comments before the next key kept there."""
    if key in data:
        data[key] = value
        return
    rank = KEY_ORDER.index(key) if key in KEY_ORDER else len(KEY_ORDER)
    keys = list(data.keys())
    at = 0
    for i, k in enumerate(keys):
        if k in KEY_ORDER and KEY_ORDER.index(k) < rank:
            at = i + 1
    if at == 0 and keys and keys[0] == "mission":
        at = 1
    if at >= len(keys):
        _append(data, key, value)
        return
    rest = None
    if at > 0:
        before = keys[at - 1]
        if _is_block(data[before]):
            rest = _detach_tail(data[before])
        else:
            slot = data.ca.items.get(before)
            if slot and len(slot) > 2 and isinstance(slot[2], CommentToken):
                head, sep, rest = slot[2].value.partition("\n")
                slot[2].value = head + sep
    data.insert(at, key, value)
    _attach_tail(data, key, rest or None)


def _position(node: Any, key: Any) -> tuple[Optional[int], Optional[int]]:
    try:
        line, column = node.lc.key(key)
        return line + 1, column + 1
    except Exception:  # noqa: BLE001 - a position is a courtesy
        return None, None


def _places(data: CommentedMap, create: bool) -> CommentedMap:
    places = data.get("places")
    if places is None:
        if not create:
            raise EditRefused("the mission has no 'places:' yet: add a place first")
        return CommentedMap()  # put in place by the caller, with its first place
    if not isinstance(places, dict):
        line, column = _position(data, "places")
        raise EditRefused("'places:' is not a list of named places here (it reads them from a file?): the map can "
                          "add places only to 'places: {name: {lat, lon}}'", line, column)
    return places


def _next_name(taken: Any, prefix: str = "") -> str:
    if not prefix:
        for letter in string.ascii_lowercase:
            if letter not in taken:
                return letter
        prefix = "p"
    n = 1
    while f"{prefix}{n}" in taken:
        n += 1
    return f"{prefix}{n}"


def add_place(data: CommentedMap, edit: dict) -> dict:
    """``{op: add_place, name?, lat, lon}``: a new place in ``places:``."""
    lat = _coordinate(edit, "lat", -90, 90)
    lon = _coordinate(edit, "lon", -180, 180)
    places = _places(data, create=True)
    name = _name(edit) or _next_name(places)
    if name in places:
        line, column = _position(places, name)
        raise EditRefused(f"there is a place called '{name}' already: choose another name, or move that one", line,
                          column)
    _add_entry(data, "places", places, name, _flow({"lat": lat, "lon": lon}))
    return {"name": name}


def move_place(data: CommentedMap, edit: dict) -> dict:
    """``{op: move_place, name, lat, lon}``: new coordinates for a place, its other keys (tolerance...) kept."""
    lat = _coordinate(edit, "lat", -90, 90)
    lon = _coordinate(edit, "lon", -180, 180)
    name = _name(edit)
    places = _places(data, create=False)
    if name not in places:
        from beastbt.core.errors import did_you_mean
        raise EditRefused(f"no place '{name}' in 'places:'{did_you_mean(str(name), list(places))}")
    place = places[name]
    if not isinstance(place, dict) or "lat" not in place:
        line, column = _position(places, name)
        raise EditRefused(f"place '{name}' is not written as {{lat, lon}}: the map can move only those", line, column)
    place["lat"] = lat
    place["lon"] = lon
    return {"name": name}


def add_fence(data: CommentedMap, edit: dict) -> dict:
    """``{op: add_fence, name?, keep: in|out, polygon: [[lat, lon], ...]}``: a fence, watched by a failsafe."""
    keep = edit.get("keep", edit.get("kind", "in"))
    if keep not in ("in", "out"):
        raise EditRefused(f"'keep' is 'in' (stay inside) or 'out' (keep out), not {keep!r}")
    polygon = edit.get("polygon")
    if not isinstance(polygon, list) or len(polygon) < 3 or not all(
            isinstance(c, (list, tuple)) and len(c) == 2 for c in polygon):
        raise EditRefused("'polygon' is a list of at least 3 corners, each [lat, lon]")
    corners = [_flow({"lat": _coordinate({"lat": c[0]}, "lat", -90, 90),
                      "lon": _coordinate({"lon": c[1]}, "lon", -180, 180)}) for c in polygon]
    fences = data.get("fences")
    if fences is None:
        fences = CommentedMap()
    if not isinstance(fences, dict):
        raise EditRefused("'fences:' is not a mapping of named fences", *_position(data, "fences"))
    name = _name(edit) or _next_name(fences, "keepout" if keep == "out" else "fence")
    if name in fences:
        raise EditRefused(f"there is a fence called '{name}' already: choose another name", *_position(fences, name))
    fence = CommentedMap({"polygon": _flow_seq(corners)})
    if keep == "out":
        fence["keep"] = "out"
    _add_entry(data, "fences", fences, name, fence)
    failsafe = "keepout" if keep == "out" else "geofence"
    failsafes = data.get("failsafes")
    watched = False
    if failsafes is None:
        failsafes = CommentedMap()
    if isinstance(failsafes, dict) and failsafe not in failsafes:
        _add_entry(data, "failsafes", failsafes, failsafe, _flow({"fence": name, "then": "stop"}))
        watched = True
    return {"name": name, "failsafe": failsafe if watched else None}


def add_route(data: CommentedMap, edit: dict) -> dict:
    """``{op: add_route, places: [names]}``: a ``route: {places: [...]}`` step at the end of ``steps``."""
    names = edit.get("places")
    if not isinstance(names, list) or len(names) < 1 or not all(isinstance(n, str) and n for n in names):
        raise EditRefused("'places' is the list of place names of the route, in order")
    places = data.get("places")
    known = list(places) if isinstance(places, dict) else []
    unknown = [n for n in names if n not in known]
    if unknown and isinstance(places, dict):
        from beastbt.core.errors import did_you_mean
        raise EditRefused(f"no place '{unknown[0]}' in 'places:'{did_you_mean(unknown[0], known)}")
    steps = data.get("steps")
    if steps is None:
        steps = CommentedSeq()
    if not isinstance(steps, list):
        raise EditRefused("'steps:' is not a list of steps", *_position(data, "steps"))
    _add_entry(data, "steps", steps, None, CommentedMap({"route": _flow({"places": _flow_seq(list(names))})}))
    return {"step": len(steps)}


OPS = {"add_place": add_place, "move_place": move_place, "add_fence": add_fence, "add_route": add_route}
"""The edits of ``POST /api/edit``, by ``op``."""


def apply_edit(text: str, edit: dict) -> dict:
    """``POST /api/edit``: ``{text, ...}`` the text with the edit made (plus what it named); raises EditRefused."""
    op = edit.get("op")
    if op not in OPS:
        from beastbt.core.errors import did_you_mean
        raise EditRefused(f"unknown edit {op!r}{did_you_mean(str(op), OPS)}; the edits are: {', '.join(OPS)}")
    crlf = "\r\n" in text
    work = text.replace("\r\n", "\n") if crlf else text
    no_eol = not work.endswith("\n")
    if no_eol:
        work += "\n"
    y, data, exact = load_round_trip(work)
    baseline = work if exact else _dump(y, data)
    made = OPS[op](data, edit)
    new = _dump(y, data)
    if not exact:
        new = _patched(work, baseline, new) or new
    if no_eol and new.endswith("\n"):
        new = new[:-1]
    if crlf:
        new = new.replace("\n", "\r\n")
    return {"text": new, "change": change_between(text, new), **{k: v for k, v in made.items() if v is not None}}


def change_between(old: str, new: str) -> dict:
    """The one replacement that turns ``old`` into ``new``: ``{line, column, end_line, end_column, text}``, 1-based,
    the end exclusive (what an editor applies as one undoable edit, the rest of its text and cursor untouched)."""
    start = 0
    limit = min(len(old), len(new))
    while start < limit and old[start] == new[start]:
        start += 1
    end_old, end_new = len(old), len(new)
    while end_old > start and end_new > start and old[end_old - 1] == new[end_new - 1]:
        end_old -= 1
        end_new -= 1

    def position(offset: int) -> tuple[int, int]:
        line = old.count("\n", 0, offset) + 1
        return line, offset - (old.rfind("\n", 0, offset) + 1) + 1

    (line, column), (end_line, end_column) = position(start), position(end_old)
    return {"line": line, "column": column, "end_line": end_line, "end_column": end_column,
            "text": new[start:end_new]}


__all__ = ["EditRefused", "OPS", "apply_edit", "change_between", "load_round_trip"]
