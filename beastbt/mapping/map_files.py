"""What the map commands and options check before any work: a cell size given with its unit, a map file that can be
written."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

MIN_RESOLUTION_M = 0.005
"""The finest map cell accepted (m): finer than any LiDAR's noise."""
MAX_RESOLUTION_M = 1.0
"""The coarsest map cell accepted (m)."""


def parse_resolution(text: str) -> float:
    """A map cell size such as ``5 cm`` or ``0.05 m`` in metres; ValueError saying what is expected."""
    from beastbt.core.units import UnitError, parse_quantity

    try:
        value = parse_quantity(text, "distance")
    except UnitError as exc:
        raise ValueError(f"'{text}' is not a cell size: {exc}") from None
    if not MIN_RESOLUTION_M <= value <= MAX_RESOLUTION_M:
        raise ValueError(f"'{text}' is not a map cell size between {MIN_RESOLUTION_M * 1000:g} mm and "
                         f"{MAX_RESOLUTION_M:g} m (e.g. '5 cm')")
    return value


def map_output_problem(option: str, path: Optional[str]) -> Optional[str]:
    """Why a map cannot be written to ``path`` (given with ``option``), in one sentence with the fix; None when it
    can. The YAML's folder is created when missing (``maps/`` of a fresh project); the PGM goes beside it."""
    if not path:
        return None
    target = Path(path)
    if target.suffix.lower() not in (".yaml", ".yml"):
        return f"{option} {path}: a map is written as a map_server YAML (with a PGM beside it): end the name in " \
               f".yaml, e.g. {target.with_suffix('.yaml')}"
    if target.is_dir():
        return f"{option} {path}: that is a folder; give a file name, e.g. {target / 'map.yaml'}"
    for folder in (target.parent, *target.parent.parents):
        if folder.exists():
            if not folder.is_dir():
                return f"{option} {path}: {folder} is a file, not a folder"
            break
    return None


__all__ = ["parse_resolution", "map_output_problem", "MIN_RESOLUTION_M", "MAX_RESOLUTION_M"]
