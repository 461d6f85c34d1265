"""``beastbt map show MAP [--places FILE_OR_MISSION] --out map.png``: draw a saved map with its places.

The map is any ``map_server`` YAML (beastbt's, Nav2's, slam_toolbox's); the
places come from a mission (its ``places:``, and its ``start:``) or a places
YAML (``name: {x: 1 m, y: 2 m}``). A place in an occupied or unknown cell is
said on standard error, as ``beastbt validate`` warns. Exit status: 0 drawn,
2 bad input (a map or places file that cannot be read, an output that cannot
be written).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Optional

EXIT_SUCCESS, EXIT_INVALID = 0, 2


def add_show_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt map show``."""
    p.add_argument("map", help="a map_server YAML (image, resolution, origin, ...), e.g. maps/office.yaml")
    p.add_argument("--places", metavar="FILE", default=None,
                   help="a mission (its places: and start:) or a places YAML (name: {x: 1 m, y: 2 m}) to draw")
    p.add_argument("--out", metavar="FILE", default=None, help="the PNG to write (default: the map's name .png)")


def _places(path: str) -> tuple[list, Optional[tuple[float, float, float]]]:
    """The places (objects with name, x, y, tolerance_m) and start pose of a mission or a places YAML; raises
    InvalidInput with positions."""
    from beastbt.core.errors import InvalidInput
    from beastbt.core.yaml_source import load_yaml
    doc = load_yaml(path)
    if "mission" in doc.data:
        from beastbt.mission.model import load_mission
        mission = load_mission(path)
        places = [p for p in mission.places.values() if p.on_map]
        start = mission.map_start if getattr(mission, "map_grid", None) is not None else None
        return places, start
    from beastbt.mission.geo_files import map_places_file
    errors: list = []
    holder = SimpleNamespace(data={"places": {"file": Path(path).name}},
                             problem=lambda *a, **k: None)  # the file itself is what is read
    raw = map_places_file(holder, Path(path).parent, Path(path).name, errors)  # type: ignore[arg-type]
    errors = [e for e in errors if e is not None]
    if errors:
        raise InvalidInput(errors)
    from beastbt.core.units import parse_quantity
    out = [SimpleNamespace(name=n, x=parse_quantity(v["x"], "distance"), y=parse_quantity(v["y"], "distance"),
                           tolerance_m=parse_quantity(v["tolerance"], "distance") if "tolerance" in v else None)
           for n, v in raw.items()]
    return out, None


def show(args: argparse.Namespace) -> int:
    """Read the map (and places), draw them, write the PNG; 2 on bad input."""
    from beastbt.commands.paths import output_file_problem
    from beastbt.core.errors import InvalidInput
    from beastbt.mapping.occupancy_map import load_map
    from beastbt.recording.map_views import save_map_png

    out = args.out or str(Path(args.map).with_suffix(".png"))
    problem = output_file_problem("--out", out)
    if problem is not None:
        print(f"beastbt map show: error: {problem}", file=sys.stderr)
        return EXIT_INVALID
    try:
        grid = load_map(args.map)
        places, start = _places(args.places) if args.places else ([], None)
    except InvalidInput as exc:
        for p in exc.problems:
            print(p.format() if hasattr(p, "format") else str(p), file=sys.stderr)
        return EXIT_INVALID
    for place in places:
        value = grid.value_at(place.x, place.y)
        if value < 0 or value >= grid.occupied_thresh * 100:
            where = "an unknown cell or off the map" if value < 0 else "an occupied cell"
            print(f"beastbt map show: warning: place '{place.name}' ({place.x:g}, {place.y:g}) m lies in {where}",
                  file=sys.stderr)
    save_map_png(grid, out, title=f"{Path(args.map).name}: {grid.cols} x {grid.rows} cells at "
                                  f"{grid.resolution_m * 100:g} cm", places=places, start=start or (0.0, 0.0, 0.0))
    print(f"map drawn to {out} ({len(places)} place{'s' if len(places) != 1 else ''})")
    return EXIT_SUCCESS


__all__ = ["add_show_arguments", "show"]
