"""Small worlds and missions for the navigation tests (tests/test_nav_*.py).

A test world is an open field at a fixed datum with a mild, MTK3339-like GPS
(white noise, a small bias, no multipath jumps unless asked), the robot at
the origin facing north. Places are given in metres east/north of the datum
and turned into WGS84 with the exact geodesy.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Optional

from beastbt.estimation.geodesy import LocalFrame
from beastbt.testing import MissionHarness

DATUM = (47.3769, 8.5417, 410.0)
"""Where the test field is (Zurich): lat, lon degrees, altitude m."""
FRAME = LocalFrame(*DATUM)

QUIET_GPS: dict[str, Any] = {"white_sigma_m": 1.0, "bias_sigma_m": 0.3, "jump_rate_per_s": 0.0}
"""A clean open-sky receiver: the tests are about the behaviours, not the filter's worst case."""


def latlon(east_m: float, north_m: float) -> tuple[float, float]:
    """(lat, lon) degrees of a point east_m/north_m metres from the test datum."""
    lat, lon, _ = FRAME.to_geodetic(east_m, north_m, 0.0)
    return lat, lon


def place_yaml(east_m: float, north_m: float, tolerance: Optional[str] = None) -> str:
    """A place entry ``{lat: ..., lon: ...}`` for a mission's ``places:``."""
    lat, lon = latlon(east_m, north_m)
    tol = f", tolerance: {tolerance}" if tolerance else ""
    return f"{{lat: {lat:.8f}, lon: {lon:.8f}{tol}}}"


def write_world(folder: Path, name: str = "field", gps: Optional[dict] = None, imu: Optional[dict] = None,
                walls: Optional[list] = None, start_yaw_deg: float = 90.0, battery_v: float = 12.3,
                obstacles: Optional[list] = None) -> str:
    """Write a test world file (JSON is YAML) and return its path."""
    world: dict[str, Any] = {
        "world": name,
        "datum": {"lat": DATUM[0], "lon": DATUM[1], "alt_m": DATUM[2]},
        "start": {"x": 0.0, "y": 0.0, "yaw_deg": start_yaw_deg},
        "battery": {"start_v": battery_v, "drain_v_per_s": 0.0002},
        "gps": {**QUIET_GPS, **(gps or {})},
    }
    if imu is not None:
        world["imu"] = imu
    if walls:
        world["walls"] = walls
    if obstacles:
        world["obstacles"] = obstacles
    path = folder / f"{name}.yaml"
    path.write_text(json.dumps(world, indent=1), encoding="utf-8")
    return str(path)


def harness(folder: Path, mission: str, seed: int = 1, robot: str = "sim", **world: Any) -> MissionHarness:
    """A harness for ``mission`` (YAML text) in a test world written to ``folder`` (``robot``: a profile)."""
    return MissionHarness.from_yaml(mission, world=write_world(folder, **world), seed=seed, base_dir=folder,
                                    robot=robot)


def robot_without_lidar(folder: Path) -> str:
    """robots/sim.yaml without its LiDAR (no collision monitor, no local costmap): go_to as pure pursuit alone."""
    import yaml

    root = Path(__file__).resolve().parent.parent
    data = yaml.safe_load((root / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    data.pop("lidar", None)
    path = folder / "robot_without_lidar.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return str(path)


def robot_without_global_costmap(folder: Path) -> str:
    """robots/sim.yaml with ``global_costmap: {enabled: false}``: go_to on the straight line and the local costmap
    alone, as before the global costmap."""
    import yaml

    root = Path(__file__).resolve().parent.parent
    data = yaml.safe_load((root / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    data["global_costmap"] = {"enabled": False}
    path = folder / "robot_without_global_costmap.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return str(path)


def true_distance_m(h: MissionHarness, east_m: float, north_m: float) -> float:
    """True distance (m) from the simulated robot to a point of the test field."""
    t = h.truth
    return math.hypot(t.x - east_m, t.y - north_m)


def true_distance_to_home_m(h: MissionHarness) -> float:
    """True distance (m) from the simulated robot to home (the run's first fix)."""
    assert h.run.home is not None
    e, n, _ = FRAME.to_enu(h.run.home[0], h.run.home[1], DATUM[2])
    return true_distance_m(h, e, n)


def kinds(h: MissionHarness) -> list[str]:
    """The kinds of the run's events so far, in order."""
    return [e.kind for e in h.events]


def events_of(h: MissionHarness, kind: str) -> list:
    """The run's events of one kind."""
    return [e for e in h.events if e.kind == kind]
