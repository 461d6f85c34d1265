"""WGS84 geodesy: exact conversion between latitude/longitude and a local east-north-up frame.

The conversion goes through Earth-centred Earth-fixed (ECEF) coordinates, so
it is exact (to floating point) at any distance, in every hemisphere and
across the antimeridian; no flat-earth approximation is made.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

WGS84_A_M = 6378137.0
"""Semi-major axis of the WGS84 ellipsoid, metres."""
WGS84_F = 1.0 / 298.257223563
"""Flattening of the WGS84 ellipsoid."""
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
"""First eccentricity squared."""
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)
"""Semi-minor axis, metres."""


TYPO_DISTANCE_M = 50_000.0
"""Two points of one mission farther apart than this (m) are a typo, typically latitude and longitude swapped,
not a plan: go_to refuses such a target and validate warns about such places."""

def geodetic_to_ecef(lat_deg: float, lon_deg: float, alt_m: float = 0.0) -> tuple[float, float, float]:
    """Convert WGS84 latitude, longitude (degrees) and ellipsoidal height (m) to ECEF metres."""
    lat = math.radians(lat_deg)
    lon = math.radians(lon_deg)
    s, c = math.sin(lat), math.cos(lat)
    n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)
    return ((n + alt_m) * c * math.cos(lon), (n + alt_m) * c * math.sin(lon), (n * (1.0 - WGS84_E2) + alt_m) * s)


def ecef_to_geodetic(x: float, y: float, z: float) -> tuple[float, float, float]:
    """Convert ECEF metres to WGS84 (latitude deg, longitude deg, height m).

    Uses Bowring's initial guess refined by Newton iterations; sub-millimetre
    everywhere near the Earth's surface.
    """
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    ep2 = (WGS84_A_M**2 - WGS84_B_M**2) / WGS84_B_M**2
    theta = math.atan2(z * WGS84_A_M, p * WGS84_B_M)
    lat = math.atan2(z + ep2 * WGS84_B_M * math.sin(theta) ** 3, p - WGS84_E2 * WGS84_A_M * math.cos(theta) ** 3)
    for _ in range(3):
        s = math.sin(lat)
        n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)
        alt = p / math.cos(lat) - n if abs(lat) < math.radians(89.0) else z / s - n * (1.0 - WGS84_E2)
        lat = math.atan2(z, p * (1.0 - WGS84_E2 * n / (n + alt)))
    s = math.sin(lat)
    n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)
    alt = p / math.cos(lat) - n if abs(lat) < math.radians(89.0) else z / s - n * (1.0 - WGS84_E2)
    return math.degrees(lat), math.degrees(lon), alt


@dataclass(frozen=True)
class LocalFrame:
    """A local east-north-up frame anchored at a WGS84 datum (degrees, metres).

    ``to_enu`` and ``to_geodetic`` are exact inverses of each other.
    """

    lat0_deg: float
    lon0_deg: float
    alt0_m: float = 0.0

    def _basis(self) -> tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]:
        lat = math.radians(self.lat0_deg)
        lon = math.radians(self.lon0_deg)
        sl, cl = math.sin(lat), math.cos(lat)
        so, co = math.sin(lon), math.cos(lon)
        east = (-so, co, 0.0)
        north = (-sl * co, -sl * so, cl)
        up = (cl * co, cl * so, sl)
        return east, north, up

    def to_enu(self, lat_deg: float, lon_deg: float, alt_m: float | None = None) -> tuple[float, float, float]:
        """Return (east, north, up) metres of a WGS84 point relative to the datum."""
        alt = self.alt0_m if alt_m is None else alt_m
        x0, y0, z0 = geodetic_to_ecef(self.lat0_deg, self.lon0_deg, self.alt0_m)
        x, y, z = geodetic_to_ecef(lat_deg, lon_deg, alt)
        d = (x - x0, y - y0, z - z0)
        e, n, u = self._basis()
        return (
            e[0] * d[0] + e[1] * d[1] + e[2] * d[2],
            n[0] * d[0] + n[1] * d[1] + n[2] * d[2],
            u[0] * d[0] + u[1] * d[1] + u[2] * d[2],
        )

    def to_geodetic(self, east_m: float, north_m: float, up_m: float = 0.0) -> tuple[float, float, float]:
        """Return (lat deg, lon deg, height m) of a local ENU point."""
        x0, y0, z0 = geodetic_to_ecef(self.lat0_deg, self.lon0_deg, self.alt0_m)
        e, n, u = self._basis()
        x = x0 + e[0] * east_m + n[0] * north_m + u[0] * up_m
        y = y0 + e[1] * east_m + n[1] * north_m + u[1] * up_m
        z = z0 + e[2] * east_m + n[2] * north_m + u[2] * up_m
        lat, lon, alt = ecef_to_geodetic(x, y, z)
        return lat, lon, alt


def distance_m(lat1_deg: float, lon1_deg: float, lat2_deg: float, lon2_deg: float) -> float:
    """Horizontal distance in metres between two WGS84 points (exact via a local frame)."""
    e, n, _ = LocalFrame(lat1_deg, lon1_deg).to_enu(lat2_deg, lon2_deg, 0.0)
    return math.hypot(e, n)
