"""Which of a mission's GPS places has no other place near it, in time that grows linearly with the places.

Comparing every place with every other one took 109 s for 4,000 places (issue
38). Here the places are first put in a grid of Earth-centred (ECEF) cubes as
wide as the distance that counts as near: two places nearer than that lie in
the same or in touching cubes, so one look at the 27 cubes round a place
finds a near neighbour, confirmed with :func:`distance_m` itself. Only the
places that look lonely that way are compared with every other place, which
gives exactly what the pairwise comparison gave (``distance_m`` measures in
the place's own horizontal plane, which the grid does not reproduce on the
far side of the Earth). A mission whose places are all lonely is compared
with numpy, row by row.
"""

from __future__ import annotations

import math
from typing import Any, Optional, Sequence

from beastbt.estimation.geodesy import distance_m, geodetic_to_ecef

ROWS_IN_PYTHON = 16
"""Up to this many lonely-looking places are compared with all others in plain Python; more with numpy (imported
only then: ``beastbt tree`` and ``validate`` do not load numpy for a usual mission)."""


def _cell(xyz: tuple[float, float, float], size_m: float) -> tuple[int, int, int]:
    return (math.floor(xyz[0] / size_m), math.floor(xyz[1] / size_m), math.floor(xyz[2] / size_m))


def lonely_places(places: Sequence[Any], far_m: float) -> dict[int, tuple[float, str]]:
    """For each place (an object with ``name``, ``lat``, ``lon`` in degrees) farther than ``far_m`` metres from
    every other place, by :func:`distance_m`: its index in ``places`` -> (metres to the nearest other, its name).

    The places that have one within ``far_m`` are left out. With fewer than
    two places every place is left out (there is nothing to compare with).
    """
    if len(places) < 2:
        return {}
    ecef = [geodetic_to_ecef(p.lat, p.lon, 0.0) for p in places]
    cells: dict[tuple[int, int, int], list[int]] = {}
    for i, xyz in enumerate(ecef):
        cells.setdefault(_cell(xyz, far_m), []).append(i)
    # Two places within far_m in a straight line (which, on Earth's surface, is within a metre of within far_m
    # horizontally) lie in touching cubes. A near place the cubes miss only sends the place to the full comparison
    # below, so the answer stays exact whatever the cubes find.
    near_offsets = sorted(((a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)),
                          key=lambda o: abs(o[0]) + abs(o[1]) + abs(o[2]))  # its own cube first
    looks_lonely = []
    for i, (place, xyz) in enumerate(zip(places, ecef)):
        cx, cy, cz = _cell(xyz, far_m)
        if not any(j != i and distance_m(place.lat, place.lon, places[j].lat, places[j].lon) <= far_m
                   for a, b, c in near_offsets for j in cells.get((cx + a, cy + b, cz + c), ())):
            looks_lonely.append(i)
    nearest = (_nearest_in_python if len(looks_lonely) <= ROWS_IN_PYTHON else _nearest_in_numpy)
    return {i: found for i, found in zip(looks_lonely, nearest(places, ecef, looks_lonely, far_m))
            if found is not None}


def _nearest_in_python(places: Sequence[Any], ecef: list, rows: list[int],
                       far_m: float) -> list[Optional[tuple[float, str]]]:
    """For each place of ``rows``: (metres, name) of the nearest other place when all are farther than ``far_m``,
    else None."""
    out: list[Optional[tuple[float, str]]] = []
    for i in rows:
        others = [(distance_m(places[i].lat, places[i].lon, q.lat, q.lon), q.name)
                  for j, q in enumerate(places) if j != i]
        out.append(min(others) if all(d > far_m for d, _ in others) else None)
    return out


def _nearest_in_numpy(places: Sequence[Any], ecef: list, rows: list[int],
                      far_m: float) -> list[Optional[tuple[float, str]]]:
    """:func:`_nearest_in_python` vectorised: :func:`distance_m`'s local east-north projection of the ECEF
    difference, for every other place at once."""
    import numpy as np  # only for a mission of many far-flung places

    xyz = np.asarray(ecef, dtype=float)
    out: list[Optional[tuple[float, str]]] = []
    for i in rows:
        lat, lon = math.radians(places[i].lat), math.radians(places[i].lon)
        east = np.array([-math.sin(lon), math.cos(lon), 0.0])
        north = np.array([-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)])
        d = xyz - xyz[i]
        distances = np.hypot(d @ east, d @ north)
        distances[i] = np.inf
        if not bool((distances > far_m).all()):
            out.append(None)
            continue
        least = float(distances.min())
        out.append(min((least, places[j].name) for j in np.flatnonzero(distances == least)))
    return out


__all__ = ["lonely_places", "ROWS_IN_PYTHON"]
