"""Judging a map built by SLAM against the simulated world it was built in (any world, not only the office's).

The same measures as ``tests/test_slam.py``:

* *wall cells seen*: the world's walls and the outlines of its boxes and
  cylinders (persons are not walls), moved into the map frame by the start
  pose and rasterised with ``mark_outlines``; counted only where a LiDAR beam
  cast in the true world (walls and fixed obstacles) from a keyframe's true
  pose (the recording's ``/truth``) ends. A seen wall cell is *marked* when
  the map has an occupied cell in it or next to it (a wall on a cell border
  falls in either cell);
* *ghosts*: the map's occupied cells more than 10 cm from any wall or
  obstacle outline, as a share of its occupied cells.

``python tests/slam_judge.py [WORLD_MISSION] [--seeds 1-5]`` runs the mission
with ``--build-map`` on each seed and prints the figures.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.mapping.occupancy_map import OccupancyMap, load_map  # noqa: E402
from beastbt.mapping.rasterise import mark_outlines  # noqa: E402
from beastbt.recording.reader import find_recording, read_recording  # noqa: E402
from beastbt.sim.lidar_emulator import RayCaster  # noqa: E402
from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle  # noqa: E402
from beastbt.sim.world import World, load_world  # noqa: E402

FLOOR_TOUR = REPO / "missions" / "floor_people_tour.yaml"
FLOOR_WORLD = REPO / "worlds" / "floor_people.yaml"
GHOST_M = 0.10
"""An occupied cell farther than this from every wall and obstacle outline is a ghost (m)."""


@dataclass(frozen=True)
class Judgement:
    """How a map agrees with its world: the share of seen wall cells marked, the share of occupied cells that are
    ghosts, the number of wall cells seen and of occupied cells."""

    marked: float
    ghosts: float
    seen: int
    occupied: int


def to_map_frame(world: World, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points (m) into the map frame: the robot's start pose is the map's origin."""
    c, s = math.cos(world.start_yaw), math.sin(world.start_yaw)
    dx, dy = np.asarray(x) - world.start_x, np.asarray(y) - world.start_y
    return c * dx + s * dy, -s * dx + c * dy


def fixed_obstacles(world: World) -> list:
    """The world's boxes and cylinders (what a map should hold besides the walls; persons walk)."""
    return [o for o in world.obstacles if isinstance(o, (BoxObstacle, CylinderObstacle))]


def wall_cells(world: World, grid: OccupancyMap) -> np.ndarray:
    """The world's walls and fixed obstacles' outlines rasterised on ``grid`` (map frame): a boolean mask."""
    segments, circles = [], []
    for w in world.walls:
        (x1, x2), (y1, y2) = to_map_frame(world, np.array([w.x1, w.x2]), np.array([w.y1, w.y2]))
        segments.append((x1, y1, x2, y2))
    for o in fixed_obstacles(world):
        if isinstance(o, BoxObstacle):
            xs, ys = to_map_frame(world, *np.array(o.corners()).T)
            segments += [(xs[i], ys[i], xs[(i + 1) % 4], ys[(i + 1) % 4]) for i in range(4)]
        else:
            cx, cy = to_map_frame(world, o.x, o.y)
            circles.append((float(cx), float(cy), o.radius_m))
    return mark_outlines(grid.with_data(np.zeros_like(grid.data)), segments, circles).data == 100


def true_poses(run: Path, stamps: list[float]) -> np.ndarray:
    """The robot's true poses (world frame, m, rad) at the clock times ``stamps`` (s), from the run's /truth."""
    truth = read_recording(find_recording(run), topics=("/truth",)).topic("/truth")
    t = np.array([m["t_s"] for m in truth])
    k = np.clip(np.searchsorted(t, stamps), 0, len(t) - 1)
    return np.array([(truth[i]["x"], truth[i]["y"], truth[i]["yaw"]) for i in k])


def seen_cells(world: World, grid: OccupancyMap, poses_world: np.ndarray) -> np.ndarray:
    """Cells where a beam (0.8 deg apart, 12 m) cast among the walls and fixed obstacles from each pose (world
    frame) ends."""
    caster = RayCaster(world.walls, fixed_obstacles(world))
    seen = np.zeros(grid.data.shape, dtype=bool)
    angles = np.radians(np.arange(0.0, 360.0, 0.8))
    for x, y, yaw in poses_world:
        r = caster.cast(x, y, yaw + angles)
        ok = np.isfinite(r) & (r <= 12.0)
        hx, hy = to_map_frame(world, x + r[ok] * np.cos(yaw + angles[ok]), y + r[ok] * np.sin(yaw + angles[ok]))
        col, row = grid.to_cells(hx, hy)
        inside = grid.inside(col, row)
        seen[row[inside], col[inside]] = True
    return seen


def judge(world: World, grid: OccupancyMap, poses_world: np.ndarray) -> Judgement:
    """How ``grid`` (map frame) agrees with ``world`` seen from the keyframes' true poses ``poses_world``."""
    walls = wall_cells(world, grid)
    seen = walls & seen_cells(world, grid, poses_world)
    occupied = grid.occupied()
    near_occupied = cv2.dilate(occupied.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    distance = cv2.distanceTransform((~walls).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * grid.resolution_m
    return Judgement(marked=float((seen & near_occupied).sum() / max(1, seen.sum())),
                     ghosts=float((occupied & (distance > GHOST_M)).sum() / max(1, occupied.sum())),
                     seen=int(seen.sum()), occupied=int(occupied.sum()))


def judged_world(mission: Path, world: Optional[Path] = None) -> Path:
    """The world a map built by ``mission`` is judged against: ``world`` (the run's --world), else the mission's own
    ``world:``, else the floor among people (the map was built in that world, not always in the floor's)."""
    if world is not None:
        return world
    from beastbt.mission.model import load_mission
    return load_mission(mission).world or FLOOR_WORLD


def run_and_judge(mission: Path, seed: int, tmp: Path, world: Optional[Path] = None) -> tuple[dict, Judgement]:
    """Run ``mission`` on ``seed`` with --build-map (recorded, into ``tmp``); its summary and the map's judgement."""
    from beastbt.cli import main
    from beastbt.commands.map_build import mapper_from_recording

    tmp.mkdir(parents=True, exist_ok=True)
    argv = ["run", str(mission), "--seed", str(seed), "--build-map", str(tmp / "map.yaml"),
            "--runs-dir", str(tmp / "runs"), "--summary", str(tmp / "summary.json")]
    if world is not None:
        argv += ["--world", str(world)]
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        main(argv)
    summary = json.loads((tmp / "summary.json").read_text())
    run = next((tmp / "runs").iterdir())
    # The keyframes' stamps: the same mapper rebuilt offline from the recording keeps the online one's keyframes.
    stamps = [k.stamp_s for k in mapper_from_recording(run).keyframes]
    w = load_world(str(judged_world(mission, world)))
    return summary, judge(w, load_map(tmp / "map.yaml"), true_poses(run, stamps))


if __name__ == "__main__":
    import argparse
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("mission", nargs="?", default=str(FLOOR_TOUR))
    parser.add_argument("--world", default=None)
    parser.add_argument("--seeds", default="1-5", help="e.g. 1-5")
    args = parser.parse_args()
    lo, _, hi = args.seeds.partition("-")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(int(lo), int(hi or lo) + 1):
            summary, j = run_and_judge(Path(args.mission), seed, Path(tmp) / str(seed),
                                       Path(args.world) if args.world else None)
            print(f"seed {seed}: {summary['status']}, {summary['truth']['collisions']} collisions, "
                  f"walls marked {j.marked:.1%} of {j.seen}, ghosts {j.ghosts:.1%} of {j.occupied} occupied",
                  flush=True)
