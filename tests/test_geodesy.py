"""WGS84 <-> local ENU: exact round trips, known distances, both hemispheres and the antimeridian."""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.estimation.geodesy import (
    WGS84_A_M,
    WGS84_B_M,
    WGS84_E2,
    LocalFrame,
    distance_m,
    ecef_to_geodetic,
    geodetic_to_ecef,
)

DATUMS = [
    (47.3769, 8.5417, 408.0),       # Zurich
    (-33.9, 179.9999, 0.0),         # south, just west of the antimeridian
    (-33.9, -179.9999, 20.0),       # south, just east of it
    (0.0, 0.0, 0.0),                # equator / prime meridian
    (64.1466, -21.9426, 10.0),      # Reykjavik, high latitude
    (-77.85, 166.67, 10.0),         # McMurdo, far south
]


def test_ecef_of_known_points() -> None:
    assert geodetic_to_ecef(0.0, 0.0, 0.0) == pytest.approx((WGS84_A_M, 0.0, 0.0), abs=1e-6)
    assert geodetic_to_ecef(90.0, 0.0, 0.0) == pytest.approx((0.0, 0.0, WGS84_B_M), abs=1e-6)
    assert geodetic_to_ecef(0.0, 90.0, 100.0) == pytest.approx((0.0, WGS84_A_M + 100.0, 0.0), abs=1e-6)
    assert geodetic_to_ecef(0.0, 180.0, 0.0)[0] == pytest.approx(-WGS84_A_M)


@pytest.mark.parametrize("lat,lon,alt", [(47.0, 8.0, 500.0), (-33.9, -179.9999, 0.0), (89.5, 45.0, 3000.0),
                                          (-12.0, 130.0, -50.0)])
def test_ecef_round_trip(lat: float, lon: float, alt: float) -> None:
    back = ecef_to_geodetic(*geodetic_to_ecef(lat, lon, alt))
    assert back[0] == pytest.approx(lat, abs=1e-9)
    assert back[1] == pytest.approx(lon, abs=1e-9)
    assert back[2] == pytest.approx(alt, abs=1e-4)


@pytest.mark.parametrize("datum", DATUMS)
def test_enu_round_trip_over_10_km(datum: tuple[float, float, float]) -> None:
    frame = LocalFrame(*datum)
    rng = np.random.default_rng(0)
    for e, n, u in [(10_000.0, 0.0, 0.0), (0.0, -10_000.0, 0.0), (-7071.0, 7071.0, 25.0)] + \
            [tuple(rng.uniform(-10_000, 10_000, 2)) + (rng.uniform(-50, 50),) for _ in range(5)]:
        lat, lon, alt = frame.to_geodetic(e, n, u)
        e2, n2, u2 = frame.to_enu(lat, lon, alt)
        assert math.dist((e, n, u), (e2, n2, u2)) < 0.02  # a few centimetres, over 10 km
        assert -180.0 <= lon <= 180.0


def test_geodetic_round_trip_through_enu() -> None:
    frame = LocalFrame(-33.9, 179.9999)
    for lat, lon in [(-33.95, -179.95), (-33.85, 179.92), (-33.9, 180.0)]:
        e, n, u = frame.to_enu(lat, lon, 0.0)
        back = frame.to_geodetic(e, n, u)
        assert back[0] == pytest.approx(lat, abs=1e-9)
        assert ((back[1] - lon + 180.0) % 360.0) - 180.0 == pytest.approx(0.0, abs=1e-9)


def test_antimeridian_is_a_short_step_east() -> None:
    frame = LocalFrame(-33.9, 179.9999)
    e, n, _ = frame.to_enu(-33.9, -179.9999)
    lat = math.radians(-33.9)
    prime_vertical_m = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * math.sin(lat) ** 2)
    expected_east = prime_vertical_m * math.cos(lat) * math.sin(math.radians(0.0002))
    assert e == pytest.approx(expected_east, abs=0.01)  # about 18.5 m east, not 40 000 km west
    assert abs(n) < 0.01


def test_southern_hemisphere_north_is_north() -> None:
    frame = LocalFrame(-33.9, 151.2)
    e, n, _ = frame.to_enu(-33.8, 151.2)  # less negative latitude = further north
    lat = math.radians(-33.85)
    meridian_m = WGS84_A_M * (1 - WGS84_E2) / (1 - WGS84_E2 * math.sin(lat) ** 2) ** 1.5
    assert n == pytest.approx(meridian_m * math.radians(0.1), rel=1e-4)
    assert abs(e) < 0.01


def test_known_distances() -> None:
    # 0.01 deg of longitude along the equator is an arc of a * 0.01 deg (chord differs by < 1 mm)
    assert distance_m(0.0, 0.0, 0.0, 0.01) == pytest.approx(WGS84_A_M * math.radians(0.01), abs=0.002)
    d = distance_m(47.0, 8.0, 47.01, 8.01)
    assert d == pytest.approx(distance_m(47.01, 8.01, 47.0, 8.0), abs=1e-3)  # symmetric
    assert 1300.0 < d < 1400.0
    assert distance_m(-33.9, 179.9999, -33.9, -179.9999) == pytest.approx(18.5, abs=0.1)
