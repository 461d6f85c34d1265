"""Mapping (2D SLAM): the office tour run with --build-map writes a map that agrees with the world's walls.

One recorded run of ``missions/office_tour.yaml`` with ``--build-map`` (module
fixture) is judged against the simulated world:

* *wall cells seen*: the world's walls and obstacle outlines, moved into the
  map frame by the start pose, rasterised with ``mark_outlines``; counted only
  where the robot could see them: a cell is seen when a LiDAR beam cast in the
  true world from a keyframe's true pose (the recording's ``/truth``) ends in
  it. A seen wall cell is *marked* when the map has an occupied cell in it or
  next to it (one cell: a wall on a cell border falls in either cell);
* *far cells*: the map's occupied cells more than 10 cm from any wall cell.

The same run rebuilt offline (``beastbt map build``) must agree as well, and
its pose graph must beat dead reckoning (loop closure corrects drift).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from beastbt.cli import main
from beastbt.mapping.occupancy_map import OccupancyMap, load_map
from beastbt.mapping.pose_graph import PoseGraph, compose, relative
from beastbt.mapping.rasterise import mark_outlines
from beastbt.mapping.scan_matcher import MatcherConfig, ScanMatcher
from beastbt.mapping.slam import Keyframe, MappingConfig, render_map
from beastbt.recording.reader import find_recording, read_recording
from beastbt.sim.lidar_emulator import RayCaster
from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle
from beastbt.sim.world import load_world
from conftest import REPO

TOUR = REPO / "missions" / "office_tour.yaml"
WORLD = load_world(str(REPO / "worlds" / "office.yaml"))


def cli(*argv: str) -> tuple[int, str, str]:
    """Run ``beastbt ARGV``; (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(argv))
        except SystemExit as exc:  # argparse refusing a value exits (2) with its message
            code = int(exc.code or 0)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def tour(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The office tour, recorded, with --build-map: its exit status, output, summary, map file and run folder."""
    tmp = tmp_path_factory.mktemp("tour")
    code, out, err = cli("run", str(TOUR), "--build-map", str(tmp / "maps" / "office.yaml"),
                         "--runs-dir", str(tmp / "runs"), "--summary", str(tmp / "summary.json"))
    summary = json.loads((tmp / "summary.json").read_text())
    run = next((tmp / "runs").iterdir())
    return {"code": code, "out": out, "err": err, "summary": summary, "map": tmp / "maps" / "office.yaml",
            "run": run, "tmp": tmp}


@pytest.fixture(scope="module")
def offline(tour: dict) -> object:
    """The tour's mapper rebuilt from its recording."""
    from beastbt.commands.map_build import mapper_from_recording
    return mapper_from_recording(tour["run"])


def to_map_frame(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points (m) into the map frame: the robot's start pose is the map's origin."""
    c, s = math.cos(WORLD.start_yaw), math.sin(WORLD.start_yaw)
    dx, dy = np.asarray(x) - WORLD.start_x, np.asarray(y) - WORLD.start_y
    return c * dx + s * dy, -s * dx + c * dy


def wall_cells(grid: OccupancyMap) -> np.ndarray:
    """The world's walls and obstacle outlines rasterised on ``grid`` (map frame): a boolean mask."""
    segments, circles = [], []
    for w in WORLD.walls:
        (x1, x2), (y1, y2) = to_map_frame(np.array([w.x1, w.x2]), np.array([w.y1, w.y2]))
        segments.append((x1, y1, x2, y2))
    for o in WORLD.obstacles:
        if isinstance(o, BoxObstacle):
            xs, ys = to_map_frame(*np.array(o.corners()).T)
            segments += [(xs[i], ys[i], xs[(i + 1) % 4], ys[(i + 1) % 4]) for i in range(4)]
        elif isinstance(o, CylinderObstacle):
            cx, cy = to_map_frame(o.x, o.y)
            circles.append((float(cx), float(cy), o.radius_m))
    return mark_outlines(grid.with_data(np.zeros_like(grid.data)), segments, circles).data == 100


def true_poses(run: Path, stamps: list[float]) -> np.ndarray:
    """The robot's true poses (world frame, m, rad) at the clock times ``stamps`` (s), from the run's /truth."""
    truth = read_recording(find_recording(run), topics=("/truth",)).topic("/truth")
    t = np.array([m["t_s"] for m in truth])
    k = np.clip(np.searchsorted(t, stamps), 0, len(t) - 1)
    return np.array([(truth[i]["x"], truth[i]["y"], truth[i]["yaw"]) for i in k])


def seen_cells(grid: OccupancyMap, poses_world: np.ndarray) -> np.ndarray:
    """Cells where a beam (0.8 deg apart, 12 m) cast in the true world from each pose (world frame) ends."""
    caster = RayCaster(WORLD.walls, WORLD.obstacles)
    seen = np.zeros(grid.data.shape, dtype=bool)
    angles = np.radians(np.arange(0.0, 360.0, 0.8))
    for x, y, yaw in poses_world:
        r = caster.cast(x, y, yaw + angles)
        ok = np.isfinite(r) & (r <= 12.0)
        hx, hy = to_map_frame(x + r[ok] * np.cos(yaw + angles[ok]), y + r[ok] * np.sin(yaw + angles[ok]))
        col, row = grid.to_cells(hx, hy)
        inside = grid.inside(col, row)
        seen[row[inside], col[inside]] = True
    return seen


def agreement(grid: OccupancyMap, poses_world: np.ndarray) -> tuple[float, float, int]:
    """(share of the seen wall cells marked within one cell, share of marked cells > 10 cm from a wall, seen)."""
    walls = wall_cells(grid)
    seen = walls & seen_cells(grid, poses_world)
    occupied = grid.occupied()
    near_occupied = cv2.dilate(occupied.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    distance = cv2.distanceTransform((~walls).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * grid.resolution_m
    marked = float((seen & near_occupied).sum() / max(1, seen.sum()))
    far = float((occupied & (distance > 0.10)).sum() / max(1, occupied.sum()))
    return marked, far, int(seen.sum())


def test_the_tour_succeeds_without_collisions_and_says_where_the_map_is(tour: dict) -> None:
    assert tour["code"] == 0, tour["err"]
    assert tour["summary"]["status"] == "success"
    assert tour["summary"]["truth"]["collisions"] == 0
    built = tour["summary"]["map"]
    assert built["file"] == str(tour["map"]) and tour["map"].exists()
    assert f"map written to {tour['map']}" in tour["out"]
    assert built["keyframes"] > 40 and built["loops_closed"] >= 1 and built["scans_dropped"] == 0
    import jsonschema

    from beastbt.core.schema_check import load_schema
    jsonschema.validate(tour["summary"], load_schema("summary.schema.json"))


def test_the_map_marks_the_walls_the_robot_saw(tour: dict, offline: object) -> None:
    grid = load_map(tour["map"])
    stamps = [k.stamp_s for k in offline.keyframes]  # type: ignore[attr-defined]
    marked, far, seen = agreement(grid, true_poses(tour["run"], stamps))
    assert seen > 1000  # the corridor, the office, the lab and the kitchen: not a handful of cells
    assert marked >= 0.90, f"{marked:.1%} of the {seen} wall cells seen are marked"
    assert far <= 0.05, f"{far:.1%} of the marked cells are more than 10 cm from a wall"


def test_the_map_is_a_map_server_map(tour: dict) -> None:
    text = tour["map"].read_text()
    import yaml
    doc = yaml.safe_load(text)
    assert set(doc) == {"image", "mode", "resolution", "origin", "negate", "occupied_thresh", "free_thresh"}
    assert doc["mode"] == "trinary" and doc["negate"] == 0 and doc["resolution"] == 0.05
    image = tour["map"].parent / doc["image"]
    raw = image.read_bytes()
    assert raw.startswith(b"P5\n")
    pixels = cv2.imread(str(image), cv2.IMREAD_UNCHANGED)
    assert pixels.dtype == np.uint8 and set(np.unique(pixels)) <= {0, 205, 254}
    grid = load_map(tour["map"])
    assert (grid.rows, grid.cols) == pixels.shape
    # The map frame's origin is where the robot started: free, and the YAML's origin is the lower-left pixel.
    assert grid.value_at(0.0, 0.0) == 0
    assert doc["origin"][0] < 0 < doc["origin"][0] + grid.width_m
    wx, wy = to_map_frame(np.array([0.0, 14.0]), np.array([0.0, 9.0]))
    assert doc["origin"][0] <= wx[0] + 0.1 and doc["origin"][1] <= wy[0] + 0.1  # the world's south-west corner


def test_loop_closure_corrects_the_drift_of_dead_reckoning(tour: dict, offline: object) -> None:
    mapper = offline
    truth = true_poses(tour["run"], [k.stamp_s for k in mapper.keyframes])  # type: ignore[attr-defined]
    tx, ty = to_map_frame(truth[:, 0], truth[:, 1])

    def rms(poses: list) -> float:
        p = np.array(poses)
        return float(np.sqrt(np.mean((p[:, 0] - tx) ** 2 + (p[:, 1] - ty) ** 2)))

    assert mapper.stats.loops_closed >= 1  # type: ignore[attr-defined]
    mapper.optimise()  # type: ignore[attr-defined]
    slam_rms, odom_rms = rms(mapper.poses()), rms(mapper.odometry_poses())  # type: ignore[attr-defined]
    assert slam_rms < 0.6 * odom_rms, (slam_rms, odom_rms)
    slam_map = mapper.occupancy_map()  # type: ignore[attr-defined]
    odom_map = mapper.occupancy_map(poses=mapper.odometry_poses())  # type: ignore[attr-defined]
    slam_marked, slam_far, _ = agreement(slam_map, truth)
    odom_marked, odom_far, _ = agreement(odom_map, truth)
    assert slam_marked > odom_marked + 0.1 and slam_far < odom_far / 3, (slam_marked, odom_marked, slam_far, odom_far)
    # Loop closures alone: with no scan match between keyframes (odometry only), closing the loops when the robot
    # comes back pulls the dead-reckoned keyframes back.
    from beastbt.commands.map_build import mapper_from_recording
    loops_only = mapper_from_recording(tour["run"], MappingConfig(min_match_score=2.0))
    assert loops_only.stats.matched == 0 and loops_only.stats.loops_closed >= 5
    loops_only.optimise()
    assert rms(loops_only.poses()) < 0.6 * rms(loops_only.odometry_poses()), (rms(loops_only.poses()), odom_rms)


def test_offline_build_from_the_recorded_run(tour: dict, offline: object) -> None:
    out_yaml = tour["tmp"] / "offline" / "office.yaml"
    code, out, err = cli("map", "build", str(tour["run"]), "--out", str(out_yaml), "--resolution", "5 cm")
    assert code == 0, err
    assert f"map written to {out_yaml}" in out
    grid = load_map(out_yaml)
    marked, far, _ = agreement(grid, true_poses(tour["run"], [k.stamp_s for k in offline.keyframes]))
    assert marked >= 0.90 and far <= 0.05, (marked, far)


def test_a_run_without_scans_says_how_to_get_them(tmp_path: Path) -> None:
    profile = tmp_path / "no_lidar.yaml"
    profile.write_text(no_lidar_profile())
    mission = tmp_path / "wait.yaml"
    mission.write_text("mission: wait\nsteps:\n  - wait: 1 s\n")
    code, _, err = cli("run", str(mission), "--robot", str(profile), "--sim", "--runs-dir", str(tmp_path / "runs"))
    assert code == 0, err
    run = next((tmp_path / "runs").iterdir())
    code, out, err = cli("map", "build", str(run), "--out", str(tmp_path / "m.yaml"))
    assert code == 2 and not (tmp_path / "m.yaml").exists()
    assert "no LiDAR scans" in err and "--record-sensors" in err and "--build-map" in err


def no_lidar_profile() -> str:
    """The simulator's profile without its ``lidar:`` section."""
    text = (REPO / "robots" / "sim.yaml").read_text()
    start = text.index("\nlidar:")
    end = text.index("\nimu:")
    return text[:start] + text[end:]


def test_build_map_on_a_robot_without_lidar_is_refused_before_anything_moves(tmp_path: Path) -> None:
    profile = tmp_path / "no_lidar.yaml"
    profile.write_text(no_lidar_profile())
    code, out, err = cli("run", str(TOUR), "--robot", str(profile), "--sim", "--build-map", str(tmp_path / "m.yaml"),
                         "--no-record")
    assert code == 2
    assert f"{profile}:1:1: error: --build-map needs a LiDAR" in err and "Traceback" not in err
    assert not (tmp_path / "m.yaml").exists() and "time" not in out


@pytest.mark.parametrize("argv, expected", [
    (["--build-map", "maps/office.png"], "end the name in .yaml"),
    (["--map-resolution", "5 cm"], "add --build-map"),
    (["--build-map", "m.yaml", "--map-resolution", "5 km"], "between 5 mm and 1 m"),
])
def test_bad_map_options_exit_2(argv: list, expected: str) -> None:
    code, out, err = cli("run", str(TOUR), "--no-record", *argv)
    assert code == 2 and expected in err and "time" not in out


# -- the pieces ------------------------------------------------------------------------------------------------

def room_points(spacing: float = 0.01) -> np.ndarray:
    """Points along the walls of a 6 m x 4 m room with a stub wall (m)."""
    segs = [(0, 0, 6, 0), (6, 0, 6, 4), (6, 4, 0, 4), (0, 4, 0, 0), (2.03, 0, 2.03, 1.5)]
    out = []
    for x1, y1, x2, y2 in segs:
        t = np.linspace(0, 1, int(math.hypot(x2 - x1, y2 - y1) / spacing))
        out.append(np.column_stack((x1 + t * (x2 - x1), y1 + t * (y2 - y1))))
    return np.concatenate(out)


def seen_from(points: np.ndarray, pose: tuple[float, float, float]) -> np.ndarray:
    """``points`` in the body frame of ``pose``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = points - np.array(pose[:2])
    return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))


def test_the_scan_matcher_finds_the_pose_from_a_wrong_prior() -> None:
    ref = room_points()
    true = (3.07, 2.21, 0.3)
    scan = seen_from(ref, true)[::5] + np.random.default_rng(1).normal(0.0, 0.01, (len(ref[::5]), 2))
    matcher = ScanMatcher()
    result = matcher.match(scan, matcher.field(ref), (3.0 + 0.2, 2.21 - 0.15, 0.3 + math.radians(8)))
    assert result is not None
    assert math.hypot(result.pose[0] - true[0], result.pose[1] - true[1]) < 0.02
    assert abs(result.pose[2] - true[2]) < math.radians(0.5)
    assert result.score > 0.8 and np.all(np.linalg.eigvalsh(result.covariance) > 0)
    # Far outside its window the best it finds scores badly: the caller can tell.
    lost = matcher.match(scan, matcher.field(ref), (1.0, 1.0, 2.0))
    assert lost is not None and lost.score < result.score - 0.3


def test_the_pose_graph_spreads_a_loop_closure_over_the_loop() -> None:
    # A square driven with odometry that over-turns each corner by 5 deg, then a loop closure: node 4 is node 0.
    graph = PoseGraph()
    cov = np.diag((0.05 ** 2, 0.05 ** 2, math.radians(3) ** 2))
    pose = (0.0, 0.0, 0.0)
    graph.add_node(pose)
    for i in range(1, 5):
        step = (2.0, 0.0, math.radians(95))
        pose = compose(pose, step)
        graph.add_node(pose)
        graph.add_edge(i - 1, i, step, cov, "odometry")
    end_before = math.hypot(*graph.poses[4][:2])
    graph.add_edge(0, 4, (0.0, 0.0, 0.0), np.diag((0.01 ** 2, 0.01 ** 2, math.radians(0.5) ** 2)), "loop")
    graph.optimise()
    assert graph.poses[0] == (0.0, 0.0, 0.0)
    assert end_before > 0.4 and math.hypot(*graph.poses[4][:2]) < 0.05
    assert abs(relative(graph.poses[0], graph.poses[4])[2]) < math.radians(1.0)


def test_rendering_clears_along_beams_marks_their_ends_and_skips_no_returns() -> None:
    # One keyframe at the origin: a return 2 m ahead, none (dropped before) to the left.
    kf = Keyframe(0.0, np.array([[2.0, 0.0]] * 3), (0.0, 0.0), (0.0, 0.0, 0.0), 0.0, np.empty((0, 2)))
    grid = render_map([kf] * 8, [(0.0, 0.0, 0.0)] * 8, 0.05, MappingConfig())
    assert grid.value_at(2.0, 0.0) >= 65  # occupied where the beam ended
    assert grid.value_at(1.0, 0.0) <= 19  # free along the beam (eight scans)
    assert grid.value_at(0.0, 1.0) == -1 and grid.value_at(2.5, 0.0) == -1  # unknown elsewhere


def test_on_the_robot_the_mapper_works_in_a_thread_and_the_map_is_written_at_the_end(tour: dict,
                                                                                      tmp_path: Path) -> None:
    # The part as the robot's wall clock assembles it: a worker thread behind a bounded queue, fed by tick().
    from types import SimpleNamespace

    from beastbt.blackboard.types import FusedPose
    from beastbt.core.clock import WallClock
    from beastbt.core.events import EventLog
    from beastbt.parts.map_building import MapBuildingPart
    from beastbt.recording.foxglove import scan_of
    from beastbt.robot.profile import load_profile
    from beastbt.run.session import RunOptions

    clock = WallClock()
    events = EventLog(clock)
    prepared = SimpleNamespace(options=RunOptions(build_map=str(tmp_path / "robot.yaml")), profile=load_profile("sim"),
                               events=events, clock=clock)
    part = MapBuildingPart()
    part.install(prepared)  # type: ignore[arg-type]
    assert part._worker is not None and part._worker.is_alive()
    rec = read_recording(find_recording(tour["run"]), topics=("/scan", "/estimate/odom"), keep_order=True)
    run = SimpleNamespace(bb=SimpleNamespace(pose_odom=None), latest_scan=lambda: None)
    fed = 0
    for topic, _, m in rec.order[:1200]:  # the first minute: out of the office and along the corridor
        if topic == "/scan":
            scan = scan_of(m)
            run.latest_scan = lambda scan=scan: scan
        else:
            run.bb.pose_odom = FusedPose(m["stamp_s"], m["x"], m["y"], m["yaw"], yaw_rate_rps=m["yaw_rate_rps"])
            part.tick(run, m["stamp_s"])  # type: ignore[arg-type]
            fed += 1
    part.close()
    assert not part._worker.is_alive()
    summary: dict = {}
    part.summarise(run, summary)  # type: ignore[arg-type]
    assert summary["map"]["scans"] + summary["map"]["scans_dropped"] > 100 and summary["map"]["keyframes"] > 5
    assert summary["map"]["file"] == str(tmp_path / "robot.yaml") and load_map(tmp_path / "robot.yaml").occupied().any()
    assert any(e.kind == "map" and "map written to" in e.text for e in events.events)


def test_a_run_stopped_early_still_writes_its_map(tmp_path: Path) -> None:
    out_yaml = tmp_path / "partial.yaml"
    code, out, err = cli("run", str(TOUR), "--build-map", str(out_yaml), "--max-time", "25 s", "--no-record",
                         "--summary", str(tmp_path / "s.json"))
    summary = json.loads((tmp_path / "s.json").read_text())
    assert code == 1 and summary["status"] == "stopped"
    assert f"map written to {out_yaml}" in out and summary["map"]["file"] == str(out_yaml)
    grid = load_map(out_yaml)
    assert grid.occupied().any() and grid.free().any()
    # Out of the office into the corridor only: the inside of the lab (never entered) is not on it.
    x, y = to_map_frame(8.5, 2.0)
    assert grid.value_at(float(x), float(y)) == -1 and summary["map"]["keyframes"] < 40
    # On the simulator the mapper works in the tick: the same seed gives the same map, byte for byte.
    again = tmp_path / "again.yaml"
    assert cli("run", str(TOUR), "--build-map", str(again), "--max-time", "25 s", "--no-record")[0] == 1
    assert again.with_suffix(".pgm").read_bytes() == out_yaml.with_suffix(".pgm").read_bytes()
    assert again.read_text() == out_yaml.read_text().replace("partial.pgm", "again.pgm")
