"""Fences (mission language v2): polygons to keep in or out of, from places, coordinates or a KML/GeoJSON file.

A fence is a polygon of (lat, lon) corners and ``keep: in`` (default) or
``keep: out``. Geometry is done with shapely in a local east-north frame
(metres) centred on the fence, so a ``margin`` is in metres: a ``keep: in``
fence is crossed when the robot is closer than the margin to its edge or
outside it; a ``keep: out`` fence when it is inside it or closer than the
margin to it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from beastbt.estimation.geodesy import LocalFrame


@dataclass
class Fence:
    """A named polygon: ``corners`` (lat, lon) in order, ``keep`` in or out."""

    name: str
    corners: list[tuple[float, float]]
    keep: str = "in"
    _frame: Any = field(default=None, repr=False)
    _shape: Any = field(default=None, repr=False)

    def _geometry(self) -> tuple[LocalFrame, Any]:
        if self._shape is None:
            from shapely.geometry import Polygon
            lat0 = sum(c[0] for c in self.corners) / len(self.corners)
            lon0 = sum(c[1] for c in self.corners) / len(self.corners)
            self._frame = LocalFrame(lat0, lon0)
            self._shape = Polygon([self._frame.to_enu(lat, lon, 0.0)[:2] for lat, lon in self.corners])
        return self._frame, self._shape

    def contains(self, lat: float, lon: float) -> bool:
        """True when (lat, lon) is inside the polygon (on its edge counts as inside)."""
        from shapely.geometry import Point
        frame, shape = self._geometry()
        e, n, _ = frame.to_enu(lat, lon, 0.0)
        return bool(shape.covers(Point(e, n)))

    def crossed(self, lat: float, lon: float, margin_m: float = 0.0) -> bool:
        """True when a robot at (lat, lon) has crossed the fence, with ``margin_m`` (m) to spare."""
        from shapely.geometry import Point
        frame, shape = self._geometry()
        e, n, _ = frame.to_enu(lat, lon, 0.0)
        point = Point(e, n)
        if self.keep == "in":
            return not shape.covers(point) or shape.exterior.distance(point) < margin_m
        return shape.covers(point) or shape.distance(point) < margin_m

    def valid_problem(self) -> str | None:
        """Why the polygon is not a usable fence (fewer than 3 corners, crossing itself), or None."""
        if len(self.corners) < 3:
            return f"fence '{self.name}' needs at least 3 corners, has {len(self.corners)}"
        _, shape = self._geometry()
        if not shape.is_valid or shape.area <= 0.0:
            return f"fence '{self.name}' is not a simple polygon (its edges cross, or it has no area)"
        return None


__all__ = ["Fence"]
