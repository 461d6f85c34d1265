"""Teach and repeat: the path a recorded run drove, thinned and written as a GPX route (``beastbt route from-run``).

The path is the fused estimate's latitude and longitude (``/estimate/fused``)
where its position was valid, else the GPS fixes (``/gps/fix``). Points are
kept one every ``every_m`` metres (the first and the last always), so that
``route: {file: path.gpx}`` repeats the drive, for example one driven by
joystick. Every recorded run on a robot with a GPS has both, whether its
mission reads the position or not (a teleop drive: the recording's position
track, :mod:`beastbt.recording.track`), so any such run can be taught, with
no flag; recordings made before the track have only what their mission read.
"""

from __future__ import annotations

from pathlib import Path
from typing import Union

from beastbt.behaviours.navigation import DrivenPath
from beastbt.estimation.geodesy import distance_m
from beastbt.recording.reader import find_recording, read_recording


def driven_path(run: Union[str, Path]) -> tuple[list[tuple[float, float]], str]:
    """The (lat, lon) path of a recorded run, and where it came from (``fused`` or ``gps``); ValueError if none."""
    recording = read_recording(find_recording(run), topics=("/estimate/fused", "/gps/fix"))
    fused = [(m["lat"], m["lon"]) for m in recording.topic("/estimate/fused")
             if m.get("position_valid") and m.get("lat") is not None]
    if fused:
        return fused, "fused"
    fixes = [(m["latitude"], m["longitude"]) for m in recording.topic("/gps/fix")
             if m.get("latitude") is not None and m.get("longitude") is not None]
    if fixes:
        return fixes, "gps"
    raise ValueError(f"{run}: the recording has no position on Earth (no valid fused position, no GPS fix): "
                     f"teach with a run on a robot with a GPS (its profile's gps:) that got a fix; a recording "
                     f"made before every run kept its position needs --record-sensors when its mission never "
                     f"read the position")


def thin(points: list[tuple[float, float]], every_m: float) -> list[tuple[float, float]]:
    """One point every ``every_m`` metres along ``points`` (m), the first and the last kept."""
    if not points:
        return []
    path = DrivenPath(every_m)
    for lat, lon in points:
        path.add(lat, lon)
    kept = path.points
    if kept[-1] != points[-1] and distance_m(kept[-1][0], kept[-1][1], *points[-1]) > 0.05 * every_m:
        kept.append(points[-1])
    return kept


def write_gpx(points: list[tuple[float, float]], out: Path, name: str) -> None:
    """Write ``points`` (lat, lon) as one GPX route called ``name``."""
    import gpxpy.gpx
    gpx = gpxpy.gpx.GPX()
    gpx.creator = "beastbt route from-run"
    route = gpxpy.gpx.GPXRoute(name=name)
    route.points.extend(gpxpy.gpx.GPXRoutePoint(latitude=lat, longitude=lon) for lat, lon in points)
    gpx.routes.append(route)
    out.write_text(gpx.to_xml(), encoding="utf-8")


__all__ = ["driven_path", "thin", "write_gpx"]
