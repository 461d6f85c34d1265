"""The camera's words of the mission language, read into typed values: ``photo``, ``alert``, ``dock``, ``undock``,
``track`` and the ``{sees: ...}`` condition.

The schema has already checked their shape; here they become the dataclasses of
:mod:`beastbt.mission.steps` (SI units), and :func:`check_sees` adds what the schema
cannot see (a colour range the detector cannot use, an area above 100 %). Their
behaviours are in :mod:`beastbt.behaviours.vision_steps`, built by :mod:`beastbt.parts.vision`.
"""

from __future__ import annotations

from typing import Any, Iterator

from beastbt.core.units import parse_quantity
from beastbt.core.yaml_source import PathKey
from beastbt.mission import steps as st
from beastbt.vision.tag_families import TAG_IDS

DOCK_DEFAULTS = {"distance": "0.25 m", "size": "16 cm", "family": "apriltag_36h11"}
"""What ``dock:`` takes when the mission leaves a key out (the schema says the same)."""
UNDOCK_DISTANCE = "0.5 m"
"""How far ``undock`` backs off by default."""
MIN_AREA_DEFAULT = "1 %"
"""``{sees: {colour: ...}}`` without ``min_area``."""


def vision_step(kind: str, v: Any, where: dict) -> st.Step:
    """The typed step of a checked ``photo``, ``alert``, ``dock``, ``undock`` or ``track`` (``where``: its ``at`` and
    ``path``)."""
    if kind == "photo":
        name = v.get("name") if isinstance(v, dict) else None
        return st.Photo(name=None if name is None else str(name), **where)
    if kind == "alert":
        if isinstance(v, dict):
            return st.Alert(text=str(v["text"]), photo=bool(v.get("photo", False)), **where)
        return st.Alert(text=str(v), **where)
    if kind == "dock":
        speed = v.get("speed")
        return st.Dock(tag=int(v["tag"]), distance_m=parse_quantity(v.get("distance", DOCK_DEFAULTS["distance"]), "distance"),
                       size_m=parse_quantity(v.get("size", DOCK_DEFAULTS["size"]), "distance"),
                       family=str(v.get("family", DOCK_DEFAULTS["family"])),
                       speed_mps=None if speed is None else parse_quantity(speed, "speed"), **where)
    if kind == "track":
        return st.Track(colour=colour_of(v["colour"]), duration_s=parse_quantity(v["for"], "duration"), **where)
    distance = v.get("distance", UNDOCK_DISTANCE) if isinstance(v, dict) else UNDOCK_DISTANCE
    return st.Undock(distance_m=parse_quantity(distance, "distance"), **where)


def colour_of(raw: Any) -> Any:
    """A checked colour as a typed value keeps it (hashable): a name, or the HSV box's two corners as tuples."""
    if isinstance(raw, dict):
        lo, hi = raw["hsv"]
        return (tuple(int(x) for x in lo), tuple(int(x) for x in hi))
    return str(raw)


def sees_of(raw: Any) -> st.Sees:
    """The typed condition of a checked ``sees:`` value."""
    if raw == "motion":
        return st.Sees(what="motion")
    if "tag" in raw:
        within, size = raw.get("within"), raw.get("size")
        return st.Sees(what="tag", tag_id=int(raw["tag"]), family=str(raw.get("family", DOCK_DEFAULTS["family"])),
                       within_m=None if within is None else parse_quantity(within, "distance"),
                       size_m=None if size is None else parse_quantity(size, "distance"))
    if "qr" in raw:
        return st.Sees(what="qr", text=str(raw["qr"]))
    return st.Sees(what="colour", colour=colour_of(raw["colour"]),
                   min_area_frac=parse_quantity(raw.get("min_area", MIN_AREA_DEFAULT), "fraction"))


def check_tag(raw: Any) -> Iterator[tuple[PathKey, str, str]]:
    """A ``tag:`` id its ``family:`` does not have, in a ``dock:`` or ``sees:`` mapping: (path, message, hint)."""
    if not isinstance(raw, dict) or not isinstance(raw.get("tag"), int) or isinstance(raw.get("tag"), bool):
        return  # the schema's to report
    family = raw.get("family", DOCK_DEFAULTS["family"])
    count = TAG_IDS.get(family) if isinstance(family, str) else None
    if count is not None and raw["tag"] >= count:
        having = [f"{name} (0 to {n - 1})" for name, n in TAG_IDS.items() if raw["tag"] < n]
        yield (("tag",), f"{family} has tags 0 to {count - 1}, not {raw['tag']}",
               "check the number printed with the tag"
               + (f", or name its family with 'family:': {', '.join(having)}" if having else ""))


def check_sees(raw: Any) -> Iterator[tuple[PathKey, str, str]]:
    """What is wrong with a ``sees:`` value beyond its shape: (path below ``sees``, message, hint) each."""
    if not isinstance(raw, dict):
        return
    yield from check_tag(raw)
    if isinstance(raw.get("colour"), dict):  # a name the schema checks; an HSV box here
        from beastbt.vision.colour import ColourRange
        try:
            ColourRange.parse(raw["colour"])
        except (ValueError, TypeError) as exc:
            yield ("colour",), f"colour: {exc}", "write red, green, blue, yellow or {hsv: [[h, s, v], [h, s, v]]}"
    if "colour" in raw and "min_area" in raw:
        try:
            area = parse_quantity(raw["min_area"], "fraction")
        except ValueError:
            return  # the schema's to report
        if not 0.0 < area <= 1.0:
            yield (("min_area",), f"min_area must be more than 0 % and at most 100 %, got {raw['min_area']!r}",
                   "write a share of the picture such as '2 %'")
    for key, example in (("within", "2 m"), ("size", "30 cm")):
        if key in raw:
            try:
                if parse_quantity(raw[key], "distance") <= 0:
                    yield (key,), f"{key} must be greater than zero, got {raw[key]!r}", f"write a distance such as '{example}'"
            except ValueError:
                continue  # the schema's to report


__all__ = ["vision_step", "sees_of", "check_sees", "check_tag", "TAG_IDS", "DOCK_DEFAULTS", "UNDOCK_DISTANCE"]
