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

import string
from typing import Any, Optional

from ruamel.yaml.comments import CommentedMap, CommentedSeq
from ruamel.yaml.error import CommentMark
from ruamel.yaml.tokens import CommentToken

from beastbt.core.yaml_round_trip import (INDENTS, EditRefused, _dump, _explicit_start, _patched,  # noqa: F401
                                          load_round_trip)

LATLON_DECIMALS = 7
"""Decimals of a latitude or longitude written by an edit (1e-7 deg is about 1 cm)."""
MAP_DECIMALS = 2
"""Decimals of a map-frame coordinate (metres) written by an edit: 1 cm."""
MAX_MAP_M = 100000.0
"""The largest map-frame coordinate an edit takes (m): beyond is a slip, not a room."""
KEY_ORDER = ("mission", "description", "world", "map", "rate", "limits", "places", "fences", "tasks", "steps")
"""Where a new top-level key goes: after the last of these that comes before it and is there."""


def _coordinate(edit: dict, key: str, low: float, high: float) -> float:
    value = edit.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
        raise EditRefused(f"'{key}' must be a number from {low:g} to {high:g} (decimal degrees), not {value!r}")
    return round(float(value), LATLON_DECIMALS)


def _metres(edit: dict, key: str) -> str:
    """A map-frame coordinate of an edit (metres) as the language writes it: ``3.25 m``, two decimals (1 cm)."""
    value = edit.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not abs(value) <= MAX_MAP_M:
        raise EditRefused(f"'{key}' must be a number of metres on the map (x forward, y left of where mapping "
                          f"began), at most {MAX_MAP_M:g} m from it, not {value!r}")
    return _decimals(float(value), MAP_DECIMALS) + " m"


def _decimals(value: float, decimals: int) -> str:
    """``value`` rounded to ``decimals``, written without trailing zeros but with one decimal (``3.0``, ``-1.5``)."""
    text = f"{round(value, decimals) + 0.0:.{decimals}f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def _yaw(edit: dict) -> Optional[str]:
    """The optional ``yaw`` of an edit (degrees, counter-clockwise from the map's x) as ``90.0 deg``."""
    value = edit.get("yaw")
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not -360 <= value <= 360:
        raise EditRefused(f"'yaw' must be a number of degrees from -360 to 360, not {value!r}")
    return _decimals(float(value), 1) + " deg"


def _frame_of(data: CommentedMap, edit: dict) -> str:
    """``map`` for a mission on a map (``map:``), ``gps`` otherwise; refuses the other frame's coordinates."""
    on_map = data.get("map") is not None
    has_xy, has_latlon = "x" in edit or "y" in edit, "lat" in edit or "lon" in edit
    if on_map and has_latlon:
        raise EditRefused("this mission is on a map (it has 'map:'): its places are {x, y} in metres on the map, "
                          "not lat/lon; send x and y", *_position(data, "map"))
    if not on_map and has_xy:
        raise EditRefused("this mission has no 'map:': its places are GPS {lat, lon}, not x/y in metres; send lat "
                          "and lon, or add map: ../maps/NAME.yaml first")
    return "map" if on_map else "gps"


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
    if isinstance(places, dict) and set(places) == {"file"} and isinstance(places["file"], str):
        line, column = _position(places, "file")
        raise EditRefused(f"the places come from the file {places['file']}: change them there (the map cannot "
                          "edit another file), or write places: {name: {x: 1 m, y: 2 m}} here", line, column)
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


def _where(data: CommentedMap, edit: dict) -> dict:
    """The coordinates an add or move writes: ``{lat, lon}`` (GPS) or ``{x: 3.25 m, y: -1.5 m, yaw?}`` (map)."""
    if _frame_of(data, edit) == "gps":
        return {"lat": _coordinate(edit, "lat", -90, 90), "lon": _coordinate(edit, "lon", -180, 180)}
    where = {"x": _metres(edit, "x"), "y": _metres(edit, "y")}
    yaw = _yaw(edit)
    if yaw is not None:
        where["yaw"] = yaw
    return where


def add_place(data: CommentedMap, edit: dict) -> dict:
    """``{op: add_place, name?, lat, lon}`` (a GPS mission) or ``{op: add_place, name?, x, y, yaw?}`` (metres and
    degrees, a mission on a map): a new place in ``places:``."""
    where = _where(data, edit)
    places = _places(data, create=True)
    name = _name(edit) or _next_name(places)
    if name in places:
        line, column = _position(places, name)
        raise EditRefused(f"there is a place called '{name}' already: choose another name, or move that one", line,
                          column)
    _add_entry(data, "places", places, name, _flow(where))
    return {"name": name}


def move_place(data: CommentedMap, edit: dict) -> dict:
    """``{op: move_place, name, lat, lon}`` or, on a map, ``{op: move_place, name, x, y, yaw?}``: new coordinates
    for a place, its other keys (tolerance, a yaw not given...) kept."""
    where = _where(data, edit)
    name = _name(edit)
    places = _places(data, create=False)
    if name not in places:
        from beastbt.core.errors import did_you_mean
        raise EditRefused(f"no place '{name}' in 'places:'{did_you_mean(str(name), list(places))}")
    place = places[name]
    need = "x" if "x" in where else "lat"
    if not isinstance(place, dict) or need not in place:
        line, column = _position(places, name)
        written = "{x, y}" if need == "x" else "{lat, lon}"
        raise EditRefused(f"place '{name}' is not written as {written}: the map can move only those", line, column)
    for key, value in where.items():
        if key in place:
            place[key] = value
        else:  # a yaw the place did not have goes after its y
            place.insert(list(place.keys()).index("y") + 1, key, value)
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
