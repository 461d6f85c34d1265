"""go_to, route and return_home on a map: places in the map frame, the validate warning, and missions in the office
world driven end to end on the simulator (localised by the particle filter, planned with A*, followed round doors)."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest

from beastbt.assembly import prepare
from beastbt.core.errors import InvalidInput
from beastbt.mission.model import load_mission
from beastbt.navigation.global_planner import GlobalCostmap, GlobalPlannerConfig, plan_path
from beastbt.run.session import RunOptions, execute
from beastbt.sim.world import load_world
from tests.map_support import OFFICE_MAP, OFFICE_WORLD, office_to_map, office_truth_map, save_map, truth_map

REPO = Path(__file__).resolve().parent.parent
MAP = str(OFFICE_MAP)


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text)
    return path


def problems_of(path: Path) -> list[str]:
    with pytest.raises(InvalidInput) as err:
        load_mission(path)
    return [f"{Path(p.file).name}:{p.position.line}:{p.position.column}: {p.message}" for p in err.value.problems]


# -- places in the map frame ------------------------------------------------------------------------------

def test_places_on_the_map_are_read_in_metres_and_radians(tmp_path):
    m = load_mission(write(tmp_path, "m.yaml", f"""mission: m
map: {MAP}
places:
  kitchen: {{x: 3.2 m, y: -100 cm}}
  lab: {{x: 6 m, y: 0.5 m, yaw: 90 deg, tolerance: 0.4 m}}
steps:
  - go_to: kitchen
"""))
    k, lab = m.places["kitchen"], m.places["lab"]
    assert (k.x, k.y, k.yaw, k.lat, k.on_map) == (3.2, -1.0, None, None, True)
    assert lab.yaw == pytest.approx(math.pi / 2) and lab.tolerance_m == 0.4
    assert m.warnings == []


def test_a_places_file_of_named_poses(tmp_path):
    write(tmp_path, "rooms.yaml", "kitchen: {x: 3 m, y: 5.5 m}\nlab: {x: 6 m, y: 0.5 m, yaw: -90 deg}\n")
    m = load_mission(write(tmp_path, "m.yaml", f"mission: m\nmap: {MAP}\nplaces: {{file: rooms.yaml}}\n"
                                               "steps:\n  - route: {places: [kitchen, lab]}\n"))
    assert sorted(m.places) == ["kitchen", "lab"]
    assert m.places["lab"].yaw == pytest.approx(-math.pi / 2) and m.places["kitchen"].y == 5.5


def test_place_errors_are_positioned(tmp_path):
    mixed = write(tmp_path, "mixed.yaml", f"""mission: m
map: {MAP}
places:
  kitchen: {{x: 3 m, y: 5 m}}
  gate: {{lat: 40.4, lon: -3.7}}
steps:
  - go_to: kitchen
""")
    assert problems_of(mixed) == ["mixed.yaml:5:3: 'gate' is a GPS place (lat, lon) but 'kitchen' is a place on the "
                                  "map (x, y): one mission's places are all in one frame"]
    no_map = write(tmp_path, "nomap.yaml", "mission: m\nplaces:\n  kitchen: {x: 3 m, y: 5 m}\nsteps:\n"
                                          "  - go_to: kitchen\n")
    assert problems_of(no_map) == ["nomap.yaml:3:3: 'kitchen' is a place on a map (x, y), but the mission has no "
                                   "'map:'"]
    missing = write(tmp_path, "missing.yaml", f"mission: m\nmap: {MAP}\nplaces: {{file: rooms.yaml}}\nsteps:\n"
                                              "  - go_to: kitchen\n")
    assert problems_of(missing)[0] == "missing.yaml:3:16: the places file rooms.yaml does not exist"
    write(tmp_path, "bad_rooms.yaml", "kitchen: {x: 3 m, y: 5 m}\nlab: {x: 6 m, y: six metres}\nstore: {x: 1 m}\n")
    bad = write(tmp_path, "bad.yaml", f"mission: m\nmap: {MAP}\nplaces: {{file: bad_rooms.yaml}}\nsteps:\n"
                                      "  - go_to: kitchen\n")
    got = problems_of(bad)
    assert got[0].startswith("bad_rooms.yaml:2:18: place 'lab': 'y' expected a distance")
    assert got[1] == "bad_rooms.yaml:3:8: place 'store' needs x and y (metres on the map)"


def test_validate_warns_of_a_place_in_a_wall_or_an_unknown_cell(tmp_path):
    wall = office_to_map(5.0, 2.0)  # the office | lab wall
    m = load_mission(write(tmp_path, "m.yaml", f"""mission: m
map: {MAP}
places:
  kitchen: {{x: 3 m, y: 5.5 m}}
  wall: {{x: {wall[0]} m, y: {wall[1]} m}}
  outside: {{x: -2.8 m, y: 0 m}}
steps:
  - route: {{places: [kitchen, wall, outside]}}
"""))
    said = [(w.position.line, w.position.column, w.message) for w in m.warnings]
    assert [s[:2] for s in said] == [(5, 9), (6, 12)]
    assert "occupied cell of the map" in said[0][2] and "unknown cell of the map" in said[1][2]


# -- driving on the office map ------------------------------------------------------------------------------

def run_traced(path: Path, max_time_s: float, robot: str = "sim") -> tuple[dict, np.ndarray, object]:
    """Run a mission to its end; its summary, the true (x, y) in the world each tick, and the run's map planner."""
    prepared = prepare(str(path), RunOptions(record=False, seed=1, max_time_s=max_time_s, robot=robot,
                                             simulate=robot != "sim"))
    trail: list = []
    prepared.run.hooks.append(lambda run, now_s: trail.append((run.io.sim.truth.x, run.io.sim.truth.y)))
    summary = execute(prepared, out=io.StringIO())
    return summary, np.array(trail), prepared.run.ctx.services.plugins["map_planner"]


def crossings(trail: np.ndarray, wall_y: float) -> list[float]:
    """The x (m) where the path crossed the line y = wall_y."""
    side = np.sign(trail[:, 1] - wall_y)
    i = np.nonzero(side[:-1] * side[1:] < 0)[0]
    return [float(trail[k, 0]) for k in i]


def shortest_m(grid, points: list[tuple[float, float]]) -> float:
    """The shortest way through ``points`` (map, m) on the truth map: no cost weight, the bare footprint."""
    costmap = GlobalCostmap(grid, GlobalPlannerConfig(cost_weight=0.0, footprint_padding_m=0.0), 0.15)
    return sum(plan_path(costmap, a, b).length_m for a, b in zip(points[:-1], points[1:]))


def test_office_rooms_through_the_doors_success_no_collisions_and_a_short_path():
    summary, trail, planner = run_traced(REPO / "missions" / "office_rooms.yaml", 400.0)
    assert summary["status"] == "success", summary["events"][-3:]
    assert summary["truth"]["collisions"] == 0
    visits = {v["name"]: v for v in summary["map_waypoints"]}
    assert [v["name"] for v in summary["map_waypoints"]] == ["kitchen", "lab", "home"]
    assert all(v["reached"] and v["arrival_error_m"] < 0.4 for v in visits.values())
    # through the doors: every crossing of the corridor's walls is within a door (robot radius 0.15 m inside it)
    doors_south = [(2.0, 3.0), (7.0, 8.0), (11.5, 12.5)]
    for wall_y, doors in ((4.0, doors_south), (5.5, [(4.0, 5.0), (10.0, 11.0)])):
        xs = crossings(trail, wall_y)
        assert xs, wall_y
        assert all(any(a + 0.15 <= x <= b - 0.15 for a, b in doors) for x in xs), (wall_y, xs)
    assert len(crossings(trail, 4.0)) == 4 and len(crossings(trail, 5.5)) == 2  # office out, kitchen in/out...
    stops = [(0.0, 0.0), (visits["kitchen"]["x"], visits["kitchen"]["y"]), (visits["lab"]["x"], visits["lab"]["y"]),
             (0.0, 0.0)]
    best = shortest_m(office_truth_map(), stops)
    assert summary["distance_m"] <= 1.3 * best, (summary["distance_m"], best)
    assert planner.plans >= 3
    # The obstacle layer holds what the map does not show, and this office has nothing the map lacks: no marks away
    # from its walls. (Scans placed with the localiser's map -> odom on the wheels' odometry, which drifts 10-15
    # deg from the gyro's in a tour, drew the walls again turned about the robot: 1,000 cells, across the
    # corridor, and home was "enclosed".)
    static = GlobalCostmap(planner.grid, GlobalPlannerConfig(), 0.15)
    assert np.count_nonzero(planner._layer.marked & (static.distance_m > 0.2)) <= 10


def office_variant(folder: Path, extra_walls: str = "", boxes: str = "", split_office_lab: bool = False) -> Path:
    """The office world with changes (in a copy, with its truth map, made without ``boxes``: things the map does
    not know); the mission folder."""
    text = OFFICE_WORLD.read_text()
    if split_office_lab:  # a door between the office and the lab, at y 1.5-2.5
        text = text.replace("  - [5.0, 0.0, 5.0, 4.0]       # office | lab",
                            "  - [5.0, 0.0, 5.0, 1.5]\n  - [5.0, 2.5, 5.0, 4.0]")
    known = folder / "known.yaml"
    known.write_text(text)
    save_map(truth_map(load_world(known)), folder / "office.yaml")
    (folder / "world.yaml").write_text(text.replace("obstacles:\n", "obstacles:\n" + boxes))
    return folder


def test_a_blocked_door_is_marked_and_the_path_goes_another_way(tmp_path):
    folder = office_variant(tmp_path, boxes="  - {shape: box, x: 5.0, y: 2.0, size_m: [0.3, 1.1], yaw_deg: 0}\n",
                            split_office_lab=True)
    lab = office_to_map(7.5, 2.5)
    mission = write(folder, "m.yaml", f"""mission: blocked_door
world: world.yaml
map: office.yaml
places:
  lab: {{x: {lab[0]} m, y: {lab[1]} m}}
steps:
  - go_to: lab
""")
    # The box the map does not show spoils the scan match at the door; AMCL's recovery (random particles) can
    # then settle in a room that looks alike, which is the localiser's business (docs/localisation.md), not the
    # planner's: this robot keeps tracking its start.
    profile = folder / "robot.yaml"
    profile.write_text((REPO / "robots" / "sim.yaml").read_text().replace("geometry:", "localisation: "
                       "{recovery_alpha_slow: 0, lost_inject_share: 0}\n\ngeometry:", 1))
    summary, trail, planner = run_traced(mission, 200.0, robot=str(profile))
    assert summary["status"] == "success", summary["events"][-3:]
    assert summary["truth"]["collisions"] == 0
    assert any(e["kind"] == "replan" and "(blocked" in e["text"] for e in summary["events"])  # by the box seen
    # it went round by the corridor: out of the office's door and into the lab's
    assert sorted(round(x) for x in crossings(trail, 4.0)) in ([2, 7], [3, 7], [2, 8], [3, 8])
    assert summary["map_waypoints"][0]["path_m"] < 6.0  # the first plan: through the door between the rooms (5 m)


def test_a_blocked_only_door_fails_with_the_reason(tmp_path):
    folder = office_variant(tmp_path, boxes="  - {shape: box, x: 4.5, y: 5.5, size_m: [1.1, 0.3], yaw_deg: 0}\n")
    kitchen = office_to_map(5.5, 7.0)
    mission = write(folder, "m.yaml", f"""mission: blocked_kitchen
world: world.yaml
map: office.yaml
places:
  kitchen: {{x: {kitchen[0]} m, y: {kitchen[1]} m}}
steps:
  - go_to: kitchen
""")
    summary, _, _ = run_traced(mission, 200.0)
    assert summary["status"] == "failure"
    assert summary["truth"]["collisions"] == 0
    end = summary["events"][-1]["text"]
    # the map has a way, the box closes it: its marks are forgotten once, the recoveries run, then it fails naming why
    assert "to kitchen" in end and "cannot be reached" in end and "what the LiDAR has marked closes it" in end, end
    assert summary["recoveries"]["count"] == 4


def test_an_unreachable_place_fails_at_once_naming_why(tmp_path):
    wall = office_to_map(5.0, 2.0)
    mission = write(tmp_path, "m.yaml", f"""mission: into_the_wall
world: {OFFICE_WORLD}
map: {MAP}
places:
  wall: {{x: {wall[0]} m, y: {wall[1]} m}}
steps:
  - go_to: wall
""")
    summary, trail, _ = run_traced(mission, 30.0)
    assert summary["status"] == "failure" and summary["sim_time_s"] < 2.0
    assert "no path to wall" in summary["events"][-1]["text"]
    assert "occupied cell of the map" in summary["events"][-1]["text"]
    assert np.hypot(*(trail[-1] - trail[0])) < 0.05  # it never moved


def test_near_a_place_on_the_map_reads_the_pose_on_the_map(tmp_path):
    mission = write(tmp_path, "m.yaml", f"""mission: near_on_map
world: {OFFICE_WORLD}
map: {MAP}
places:
  mark: {{x: 1.5 m, y: 0 m}}
steps:
  - until: {{near: mark, within: 0.3 m}}
    steps:
      - drive: {{distance: 2.5 m}}
""")
    summary, trail, _ = run_traced(mission, 30.0)
    assert summary["status"] == "success"
    assert 1.1 < summary["distance_m"] < 1.35  # stopped 0.3 m short of the mark, 1.5 m ahead of the start


def test_on_failure_return_home_goes_home_on_the_map(tmp_path):
    wall = office_to_map(5.0, 2.0)
    mission = write(tmp_path, "m.yaml", f"""mission: home_on_map
world: {OFFICE_WORLD}
map: {MAP}
places:
  wall: {{x: {wall[0]} m, y: {wall[1]} m}}
steps:
  - drive: {{distance: 1 m}}
  - go_to: wall
on_failure: return_home
""")
    summary, trail, _ = run_traced(mission, 60.0)
    assert summary["status"] == "failure"
    assert "returned home" in summary["events"][-1]["text"], summary["events"][-3:]
    assert np.hypot(trail[-1][0] - 2.5, trail[-1][1] - 2.0) < 0.4  # back where it started (world 2.5, 2.0)
    assert [w["name"] for w in summary["map_waypoints"]] == ["wall", "home"]


def test_office_rooms_on_a_map_built_by_slam(tmp_path, monkeypatch):
    """The issue's done-when on a map made by the robot itself: the office tour mapped with --build-map, then the
    kitchen, the lab and home on that map."""
    from beastbt.cli import main
    monkeypatch.chdir(tmp_path)
    built = tmp_path / "office_slam.yaml"
    assert main(["run", str(REPO / "missions" / "office_tour.yaml"), "--speed", "max", "--build-map", str(built),
                 "--runs-dir", str(tmp_path / "runs")]) == 0
    text = (REPO / "missions" / "office_rooms.yaml").read_text()
    mission = write(tmp_path, "rooms.yaml", text.replace("map: ../maps/office.yaml", f"map: {built}")
                    .replace("world: ../worlds/office.yaml", f"world: {OFFICE_WORLD}"))
    summary, trail, _ = run_traced(mission, 400.0)
    assert summary["status"] == "success", summary["events"][-3:]
    assert summary["truth"]["collisions"] == 0
    assert all(v["reached"] and v["arrival_error_m"] < 0.4 for v in summary["map_waypoints"])
    best = shortest_m(office_truth_map(), [(0.0, 0.0), (3.0, 5.5), (6.0, 0.5), (0.0, 0.0)])
    assert summary["distance_m"] <= 1.3 * best, (summary["distance_m"], best)


@pytest.mark.parametrize("start", ["{x: 0.8 m, y: 0.6 m, yaw: 20 deg}", "{x: 0 m, y: 0 m, yaw: 180 deg}"])
def test_a_start_given_wrongly_is_no_wall_round_the_robot(tmp_path, start):
    """Told it stands 1 m and 20 deg off (or facing the other way), the robot's first scans, placed on the map with
    that pose, drew walls round it where the map is open, and the go_to failed in half a second ('cannot be
    reached: walls enclose it'), before the localiser, which needs motion, could find its place. Scans the map
    explains poorly are not marked, and marks that alone close a way the map has are forgotten once (Nav2 clears its
    costmap when the planner fails): it drives, the localiser finds its place, the robot reaches the kitchen."""
    kitchen = office_to_map(3.5, 7.0)
    mission = write(tmp_path, "m.yaml", f"""mission: told_wrongly
world: {OFFICE_WORLD}
map: {MAP}
start: {start}
places:
  kitchen: {{x: {kitchen[0]} m, y: {kitchen[1]} m}}
steps:
  - go_to: kitchen
""")
    summary, _, _ = run_traced(mission, 120.0)
    assert summary["status"] == "success", summary["events"][-3:]
    assert summary["truth"]["collisions"] == 0 and summary["localisation"]["localized"]
