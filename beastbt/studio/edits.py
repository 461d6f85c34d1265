"""Edits the map makes to a mission's text, with ruamel.yaml's round trip: the rest of the file is kept as it was.

Comments, key order, blank lines, quotes and flow style all survive: the text
is loaded in round-trip mode and dumped again with the indentation the file
itself uses (found by trying the usual ones until the unchanged text comes back
byte for byte). Only the part an edit touches is new. Numbers are rounded:
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


def load_round_trip(text: str) -> tuple[YAML, Any]:
    """(the YAML object that writes this text back unchanged, its data); raises EditRefused when it is not YAML."""
    best: Optional[tuple[int, YAML, Any]] = None
    for indent in INDENTS:
        y = _yaml(indent)
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
            return y, data
        differing = sum(a != b for a, b in zip(again.splitlines(), text.splitlines())) + abs(
            len(again.splitlines()) - len(text.splitlines()))
        if best is None or differing < best[0]:
            best = (differing, y, data)
    assert best is not None
    return best[1], best[2]


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
    """Append ``key: value`` to a mapping (``key`` None: ``value`` to a sequence), the lines after its end kept after."""
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
    y, data = load_round_trip(text)
    made = OPS[op](data, edit)
    return {"text": _dump(y, data), **{k: v for k, v in made.items() if v is not None}}


__all__ = ["EditRefused", "OPS", "apply_edit", "load_round_trip"]
