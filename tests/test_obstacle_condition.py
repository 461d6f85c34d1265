"""The obstacle_within condition: hand-made scans against hand geometry, the mission's checks, and whole runs.

``{obstacle_within: D, sector_deg: [from, to]}`` holds when at least
``min_points`` LiDAR returns (3 by default) lie at most D from the footprint
(a circle of the footprint radius round base_link), in the sector from
``from`` counterclockwise to ``to`` (base_link, 0 ahead, positive left).
Without a fresh scan it is unknown: it never holds, and neither does its
``not`` (docs/mission-language.md, docs/obstacles.md).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Iterable, Optional

import numpy as np
import py_trees
import pytest
import yaml

from beastbt.behaviours.context import MissionContext, RunServices
from beastbt.behaviours.obstacle_within import ObstacleSensing
from beastbt.behaviours.operator import NotAvailable
from beastbt.blackboard import catalogue
from beastbt.blackboard.types import LaserScan
from beastbt.core.clock import SimClock
from beastbt.core.errors import InvalidInput
from beastbt.core.events import EventLog
from beastbt.devices.lidar_scan import LidarMounting
from beastbt.mission.compile import Compiler, compile_mission
from beastbt.mission.model import load_mission
from beastbt.testing import MissionHarness
from conftest import REPO

Status = py_trees.common.Status
RADIUS_M = 0.15  # the footprint of robots/sim.yaml and the default
CORRIDOR = str(REPO / "worlds" / "corridor.yaml")
CORRIDOR_PERSON = str(REPO / "worlds" / "corridor_person.yaml")


# -- hand-made scans --------------------------------------------------------------------

def scan_of(returns: Iterable[tuple[float, float]], stamp_s: float = 0.0, spread_deg: float = 0.5,
            per_return: int = 3) -> LaserScan:
    """A scan in the LiDAR's frame: for each (bearing deg, range m), ``per_return`` returns ``spread_deg`` apart
    round that bearing (an object, not one stray point), and no return (NaN) everywhere else."""
    angles, ranges = list(np.radians(np.arange(-180.0, 180.0, 1.0))), [math.nan] * 360
    for bearing, rng in returns:
        for k in range(per_return):
            angles.append(math.radians(bearing + (k - (per_return - 1) / 2) * spread_deg))
            ranges.append(rng)
    a = np.array(angles)
    return LaserScan(stamp_s, (a + math.pi) % (2 * math.pi) - math.pi, np.array(ranges), np.zeros(len(a)), 10.0,
                     "ld19")


class Bench:
    """A context with a LiDAR, a clock, a blackboard ``scan`` and the compiled conditions of one mission."""

    def __init__(self, conditions: list[str], sensing: Optional[ObstacleSensing] = None,
                 capabilities: frozenset = frozenset({"lidar"})) -> None:
        text = "mission: t\nsteps:\n" + "".join(f"  - wait_until: {c}\n" for c in conditions)
        self.mission = load_mission("<bench>", text=text)
        self.clock = SimClock()
        self.events = EventLog(self.clock)
        catalogue.reset_blackboard()
        self.writer = catalogue.writer("bench", ("scan",))
        self.ctx = MissionContext(clock=self.clock, events=self.events, capabilities=capabilities,
                                  services=RunServices(obstacle_sensing=sensing or ObstacleSensing()))
        compiler = Compiler(self.mission, self.ctx)
        self.conditions = [compiler.condition(s.condition) for s in self.mission.steps]

    def show(self, scan: LaserScan) -> None:
        self.writer.scan = scan

    def holds(self, i: int = 0) -> bool:
        return self.conditions[i].holds()

    def answer(self, i: int = 0) -> Optional[bool]:
        return self.conditions[i].test(self.conditions[i].reader)

    def said(self) -> list[str]:
        return [e.text for e in self.events.events if e.kind == "obstacle_within"]


def gap_range(gap_m: float) -> float:
    """The range from a LiDAR at base_link's origin at which a return is ``gap_m`` from the footprint."""
    return gap_m + RADIUS_M


def test_a_return_inside_the_distance_holds_one_outside_does_not():
    b = Bench(["{obstacle_within: 0.5 m}"])
    b.show(scan_of([(0.0, gap_range(0.49))]))
    assert b.holds()
    b.show(scan_of([(0.0, gap_range(0.51))]))
    assert not b.holds() and b.answer() is False
    b.show(scan_of([(137.0, gap_range(0.30)), (-20.0, gap_range(2.0))]))  # all around: behind counts too
    assert b.holds()
    said = re.fullmatch(r" \(nearest (\S+) m at (\S+) deg, (\d+) returns\)", b.conditions[0].details())
    assert said and float(said[1]) == pytest.approx(0.30) and abs(float(said[2]) - 137) <= 1 and said[3] == "3"


def test_distances_in_cm_and_bare_metres_mean_the_same():
    b = Bench(["{obstacle_within: 50 cm}", "{obstacle_within: 0.5}"])
    for rng, expected in ((gap_range(0.495), True), (gap_range(0.505), False)):
        b.show(scan_of([(10.0, rng)]))
        assert b.holds(0) is expected and b.holds(1) is expected


def test_fewer_returns_than_min_points_are_not_an_obstacle():
    b = Bench(["{obstacle_within: 0.5 m}"])
    b.show(scan_of([(0.0, gap_range(0.2))], per_return=2))  # two stray returns: below the default min_points 3
    assert not b.holds()
    b.show(scan_of([(0.0, gap_range(0.2))], per_return=3))
    assert b.holds()
    one = Bench(["{obstacle_within: 0.5 m}"], ObstacleSensing(min_points=1))
    one.show(scan_of([(0.0, gap_range(0.2))], per_return=1))
    assert one.holds()


@pytest.mark.parametrize("bearing, inside", [(0.0, True), (-29.0, True), (29.0, True), (31.0, False),
                                             (-31.0, False), (90.0, False), (180.0, False)])
def test_a_sector_ahead(bearing, inside):
    b = Bench(["{obstacle_within: 0.5 m, sector_deg: [-30, 30]}"])
    b.show(scan_of([(bearing, gap_range(0.3))], spread_deg=0.2))
    assert b.holds() is inside


@pytest.mark.parametrize("bearing, inside", [(180.0, True), (-170.0, True), (160.0, True), (151.0, True),
                                             (140.0, False), (-140.0, False), (0.0, False), (90.0, False)])
def test_a_sector_behind_wraps_round_180_deg(bearing, inside):
    b = Bench(["{obstacle_within: 0.5 m, sector_deg: [150, -150]}"])
    b.show(scan_of([(bearing, gap_range(0.3))], spread_deg=0.2))
    assert b.holds() is inside


def test_sector_ends_with_units_and_a_sector_to_the_left():
    b = Bench(["{obstacle_within: 0.5 m, sector_deg: ['60 deg', '2.0944 rad']}"])  # 60 to 120 deg: the left side
    for bearing, inside in ((90.0, True), (-90.0, False), (0.0, False)):
        b.show(scan_of([(bearing, gap_range(0.3))], spread_deg=0.2))
        assert b.holds() is inside, bearing


def test_the_long_way_round_and_all_around():
    b = Bench(["{obstacle_within: 0.5 m, sector_deg: [30, -30]}",
               "{obstacle_within: 0.5 m, sector_deg: [-180, 180]}"])
    b.show(scan_of([(0.0, gap_range(0.3))], spread_deg=0.2))  # straight ahead: outside [30, -30]
    assert not b.holds(0) and b.holds(1)
    b.show(scan_of([(100.0, gap_range(0.3))], spread_deg=0.2))
    assert b.holds(0) and b.holds(1)


def test_the_lidar_mounting_is_respected():
    """A LiDAR 0.2 m behind the centre, turned round (its 0 degree mark looks backwards): a return it sees at
    180 deg, 0.8 m away, is 0.6 m ahead of base_link, a 0.45 m gap straight ahead."""
    back = ObstacleSensing(mounting=LidarMounting(x_m=-0.2, y_m=0.0, z_m=0.1, yaw_deg=180.0))
    conditions = ["{obstacle_within: 0.5 m, sector_deg: [-30, 30]}", "{obstacle_within: 0.4 m}",
                  "{obstacle_within: 0.5 m, sector_deg: [150, -150]}"]
    b = Bench(conditions, back)
    b.show(scan_of([(180.0, 0.8)], spread_deg=0.1))
    assert [b.holds(i) for i in range(3)] == [True, False, False]
    assert "nearest 0.45 m at 0 deg" in b.conditions[0].details()
    centred = Bench(conditions)  # the same scan from a LiDAR at the centre, 0 mark ahead: 0.65 m behind
    centred.show(scan_of([(180.0, 0.8)], spread_deg=0.1))
    assert [centred.holds(i) for i in range(3)] == [False, False, False]
    left = Bench(["{obstacle_within: 0.5 m, sector_deg: [60, 120]}"],
                 ObstacleSensing(mounting=LidarMounting(x_m=0.0, y_m=0.3, z_m=0.1, yaw_deg=90.0)))
    left.show(scan_of([(0.0, 0.3)], spread_deg=0.1))  # its 0 mark looks left: 0.6 m left of the centre
    assert left.holds() and "at 90 deg" in left.conditions[0].details()


def test_a_stale_scan_never_holds_nor_does_its_not_said_once_then_back():
    b = Bench(["{obstacle_within: 0.5 m}", "{not: {obstacle_within: 0.5 m}}",
               "{any: [{obstacle_within: 0.5 m}, {elapsed: 1 h}]}",
               "{all: [{obstacle_within: 0.5 m}, {elapsed: 1 h}]}"])
    b.show(scan_of([(0.0, gap_range(2.0))], stamp_s=0.0))  # nothing near
    b.clock.advance(0.3)
    assert [b.answer(i) for i in range(4)] == [False, True, False, False]  # 0.3 s old still counts
    b.clock.advance(0.05)
    assert [b.answer(i) for i in range(4)] == [None, None, None, False]  # unknown; all() is False by its elapsed
    assert not any(b.holds(i) for i in range(4))
    for _ in range(20):
        b.clock.advance(0.1)
        b.holds(0), b.holds(1)
    silent = b.said()
    assert len(silent) == 1 and "no LiDAR scan for 0.35 s (older than 0.3 s)" in silent[0]
    b.show(scan_of([(0.0, gap_range(0.2))], stamp_s=b.clock.now()))
    assert b.holds(0) and not b.holds(1) and b.holds(2)
    assert len(b.said()) == 2 and "scans are back" in b.said()[1]


@pytest.mark.parametrize("a, b, nota, both, either", [
    (True, True, False, True, True), (True, False, False, False, True), (False, False, True, False, False),
    (True, None, False, None, True), (False, None, True, False, None), (None, None, None, None, None),
    (np.bool_(True), None, False, None, True), (np.bool_(False), np.bool_(True), True, False, True),
])
def test_not_all_and_any_of_unknown_answers(a, b, nota, both, either):
    """Kleene's three-valued logic: unknown (None) stays unknown unless the known part decides; a numpy bool
    counts as its bool; only True holds."""
    from beastbt.behaviours.conditions import Condition, all_of, any_of, not_of
    ta, tb = (lambda r: a), (lambda r: b)
    for test, expected in ((not_of(ta), nota), (all_of([ta, tb]), both), (any_of([ta, tb]), either),
                           (all_of([tb, ta]), both), (any_of([tb, ta]), either)):
        answer = test(None)
        assert (answer is None) == (expected is None) and (answer is None or bool(answer) == expected)
        assert Condition("c", test, None).holds() is (expected is True)  # type: ignore[arg-type]


def test_the_collision_monitors_source_timeout_is_the_age_limit():
    b = Bench(["{obstacle_within: 0.5 m}"], ObstacleSensing(max_age_s=1.0))
    b.show(scan_of([(0.0, gap_range(0.2))], stamp_s=0.0))
    b.clock.advance(0.9)
    assert b.holds()
    b.clock.advance(0.2)
    assert b.answer() is None


def test_no_scan_yet_is_said_only_after_the_lidars_spin_up_grace():
    b = Bench(["{obstacle_within: 0.5 m}"])
    for _ in range(29):
        assert b.answer() is None
        b.clock.advance(0.1)
    assert b.said() == []
    b.clock.advance(0.2)
    b.answer()
    assert len(b.said()) == 1 and "no LiDAR scan in 3.1 s" in b.said()[0]


def test_one_transform_per_scan_whatever_the_number_of_conditions():
    b = Bench(["{obstacle_within: 0.5 m}", "{obstacle_within: 1 m, sector_deg: [-30, 30]}"])
    b.show(scan_of([(0.0, gap_range(0.8))]))
    assert not b.holds(0) and b.holds(1)
    view = b.conditions[0].test.watch._view
    assert b.conditions[1].test.watch is b.conditions[0].test.watch
    b.holds(0), b.holds(1)
    assert b.conditions[0].test.watch._view is view  # the same scan: not moved to base_link again


# -- a robot without a LiDAR ---------------------------------------------------------------

def robot_without_lidar(tmp_path: Path, **changes) -> str:
    """robots/sim.yaml without its LiDAR (or with ``changes`` to its sections)."""
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    data.pop("lidar", None)
    data.update(changes)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return str(path)


def test_without_a_lidar_the_step_fails_at_once_saying_why_and_the_run_warns_first(tmp_path):
    text = ("mission: t\nsteps:\n  - say: start\n  - if: {all: [gps_fix, {not: {obstacle_within: 1 m}}]}\n"
            "    then: [stop]\n  - until: {obstacle_within: 0.6 m}\n    steps:\n      - drive: {distance: 1 m}\n")
    h = MissionHarness.from_yaml(text, world=CORRIDOR, robot=robot_without_lidar(tmp_path))
    warned = [w for w in h.prepared.warnings if "LiDAR" in w.message]
    assert [w.position.line for w in warned] == [4, 6]
    assert "this if step fails at once" in warned[0].message and "robots/sim.yaml" in warned[0].hint
    unavailable = [n for n in h.run.nodes if isinstance(n, NotAvailable)]
    assert [n.name for n in unavailable] == ["if (obstacle within 1 m: not on this robot)",
                                             "until (obstacle within 0.6 m: not on this robot)"]
    assert h.run_to_end(10) == "failure"
    assert h.now_s < 0.5 and h.summary()["truth"]["distance_m"] == 0.0
    end = [e.text for e in h.events if e.kind == "mission_end"][0]
    assert "'obstacle_within' needs a LiDAR, and this robot has none" in end


def test_the_lidar_part_gives_the_conditions_the_profiles_geometry(tmp_path):
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    data["lidar"]["mounting"] = {"x_m": 0.05, "y_m": -0.02, "z_m": 0.1, "yaw_deg": 90}
    data["geometry"]["footprint_radius_m"] = 0.2
    data["collision_monitor"] = {"min_points": 5, "source_timeout_s": "500 ms"}
    robot = tmp_path / "robot.yaml"
    robot.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - wait_until: {obstacle_within: 1 m}\n", world=CORRIDOR,
                                 robot=str(robot))
    assert h.run.ctx.services.obstacle_sensing == ObstacleSensing(LidarMounting(0.05, -0.02, 0.1, 90.0), 0.2, 0.5, 5)
    assert "scan" in h.run.reads()


# -- what the author writes ---------------------------------------------------------------

@pytest.mark.parametrize("condition, line_col, words, hint", [
    ("{obstacle_within: -0.5 m}", (3, 35), "obstacle_within must be greater than zero, got '-0.5 m'",
     "positive distance"),
    ("{obstacle_within: 0 m}", (3, 35), "greater than zero", "positive distance"),
    ("{obstacle_within: 0.5 m, sector_deg: [30, 30]}", (3, 54), "'sector_deg' [30, 30] is empty",
     "[-30, 30] for the 60 degrees ahead"),
    ("{obstacle_within: 0.5 m, sector_deg: [-30, 0, 30]}", (3, 54), "'sector_deg' takes exactly 2 items, has 3",
     "[from, to]"),
    ("{obstacle_within: 0.5 m, sector_deg: [-30]}", (3, 54), "'sector_deg' needs at least 2 items, has 1",
     "[from, to]"),
    ("{obstacle_within: 0.5 m, sectors: [-30, 30]}", (3, 42), "unknown key 'sectors' in 'wait_until'; did you "
     "mean 'sector_deg'?", "allowed here: obstacle_within, sector_deg"),
    ("{obstacle_within: 0.5 m, sector_deg: [-30, 400]}", (3, 60), "400 is out of range in 'sector_deg'",
     "from -360 to 360"),
    ("{obstacle_within: 0.5 m, sector_deg: [-30, 30 degrees]}", (3, 60), "'30 degrees'", "'30 deg'"),
    ("{obstacle_within: 2 s}", (3, 35), "expected a distance such as '3 m'", "a bare number is metres"),
    ("{obstacle_within: 0.5 m, sector_deg: 30}", (3, 54), "expected a list in 'sector_deg'", "[from, to]"),
])
def test_a_mistake_is_reported_at_its_place_with_what_was_expected_and_a_hint(condition, line_col, words, hint):
    text = f"mission: t\nsteps:\n  - wait_until: {condition}\n"
    with pytest.raises(InvalidInput) as exc:
        load_mission("/tmp/m.yaml", text=text)
    problems = exc.value.problems
    assert len(problems) == 1, exc.value.format()
    p = problems[0]
    assert (p.file, p.position.line, p.position.column) == ("/tmp/m.yaml", *line_col), exc.value.format()
    assert words in p.message and hint in (p.hint or ""), exc.value.format()
    assert exc.value.format().startswith(f"/tmp/m.yaml:{line_col[0]}:{line_col[1]}: error:")


def test_a_sector_written_the_long_way_round_is_a_warning():
    m = load_mission("/tmp/m.yaml", text="mission: t\nsteps:\n  - if: {not: {obstacle_within: 0.5 m, "
                                         "sector_deg: [30, -30]}}\n    then: [stop]\n"
                                         "  - wait_until: {obstacle_within: 1 m, sector_deg: [150, -150]}\n")
    assert len(m.warnings) == 1, m.warnings
    w = m.warnings[0]
    assert w.position.line == 3 and "the 300 degrees round the back" in w.message and "[-30, 30]" in w.hint


def test_the_condition_in_every_place_a_condition_goes_and_its_words():
    m = load_mission("/tmp/m.yaml", text="""mission: t
steps:
  - if: {obstacle_within: 1 m}
    then: [stop]
  - while: {not: {obstacle_within: 0.3 m, sector_deg: [-45, 45]}}
    steps: [{wait: 1 s}]
  - wait_until: {obstacle_within: 50 cm, sector_deg: ['150 deg', -150]}
    timeout: 5 s
  - until: {obstacle_within: 0.6 m}
    steps: [{drive: {distance: 10 m}}]
  - abort_if: {any: [{obstacle_within: 0.2 m}, {battery_below: 10 V}]}
    steps: [{drive: {distance: 1 m}}]
""")
    clock = SimClock()
    ctx = MissionContext(clock=clock, events=EventLog(clock), capabilities=frozenset({"lidar"}))
    names = [n.name for n in compile_mission(m, ctx).iterate()]
    for name in ("if obstacle within 1 m", "while not obstacle within 0.3 m in sector [-45, 45] deg",
                 "wait until obstacle within 0.5 m in sector [150, -150] deg (at most 5 s)",
                 "until obstacle within 0.6 m", "abort if any of (obstacle within 0.2 m, battery below 10 V)"):
        assert name in names, names
    assert ctx.condition_reads >= {"scan", "battery"}


# -- whole runs on the simulator -----------------------------------------------------------

def gap_to_end_wall(h: MissionHarness) -> float:
    """The true gap between the footprint and the corridor's east wall (x = 10 m), m."""
    return 10.0 - h.truth.x - RADIUS_M


def test_until_an_obstacle_within_ends_a_10_m_drive_stopped_before_the_corridors_end_wall():
    """The design doc's v3 example: the drive is halted, the mission succeeds, and the robot stands a little
    under 0.6 m from the wall (what the halt and the stop take: a tick, a scan's age, the gate's ramp down).
    The wait after it lets the robot come to rest before the run ends."""
    h = MissionHarness.from_yaml("mission: v3\nsteps:\n  - until: {obstacle_within: 0.6 m}\n    steps:\n"
                                 "      - drive: {distance: 10 m, speed: 0.3 m/s}\n  - wait: 1 s\n", world=CORRIDOR)
    assert h.run_to_end(60) == "success"
    halted = [e for e in h.events if e.kind == "guard"]
    assert len(halted) == 1 and "until obstacle within 0.6 m: obstacle within 0.6 m holds (nearest 0.5" in \
        halted[0].text and "halting drive 10 m" in halted[0].text
    assert abs(h.truth.v_mps) < 1e-3  # at rest (the tracks' speed decays to zero)
    v, latency_s, decel = 0.3, 0.2, 1.0  # a scan period, a tick and the scan's read; robots/sim.yaml's max_accel
    assert 0.6 - v * latency_s - v * v / (2 * decel) - 0.02 < gap_to_end_wall(h) <= 0.6 + 0.02
    truth = h.summary()["truth"]
    assert truth["collisions"] == 0 and truth["min_clearance_m"] == pytest.approx(gap_to_end_wall(h), abs=0.01)
    assert not any(e.kind == "collision_monitor" and "stop" in e.text for e in h.events)  # it never needed to


def test_abort_if_fails_the_mission_with_the_condition_in_words():
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - abort_if: {obstacle_within: 1 m, sector_deg: [-30, 30]}\n"
                                 "    steps:\n      - drive: {distance: 10 m, speed: 0.3 m/s}\n  - say: never\n",
                                 world=CORRIDOR)
    assert h.run_to_end(60) == "failure"
    end = [e.text for e in h.events if e.kind == "mission_end"][0]
    assert "abort if obstacle within 1 m in sector [-30, 30] deg: obstacle within 1 m in sector [-30, 30] deg " \
           "holds (nearest " in end and "halting drive 10 m" in end
    assert 0.8 < gap_to_end_wall(h) <= 1.02 and h.summary()["truth"]["collisions"] == 0
    assert not any(e.kind == "say" for e in h.events)


def test_wait_until_ends_when_the_person_walks_into_the_sector():
    """worlds/corridor_person.yaml: from 5 s a person (0.25 m) walks from x = 9.5 m toward the robot standing at
    x = 1 m, 0.3 m north of its line: the wait ends on the first scan that sees them within 1.5 m ahead."""
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - wait_until: {obstacle_within: 1.5 m, sector_deg: [-30, 30]}\n"
                                 "    timeout: 30 s\n  - say: someone is coming\n", world=CORRIDOR_PERSON)
    contact = h.run.io.sim.drive.contact
    wait = h.node("wait until obstacle within 1.5 m in sector [-30, 30] deg (at most 30 s)")

    def person_gap() -> float:
        (px, py), = contact.person_xy
        return math.hypot(px - h.truth.x, py - h.truth.y) - 0.25 - RADIUS_M

    while wait.status != Status.SUCCESS:
        h.tick()
        assert h.now_s < 20.0 and wait.status != Status.FAILURE
        if wait.status == Status.RUNNING:
            assert person_gap() > 1.5 - 0.02, "it waits while the person is farther"
    assert 1.5 - 0.8 * 0.2 - 0.02 < person_gap() <= 1.5 + 0.02  # seen within a scan's age at walking pace
    assert 5.0 + (9.5 - 1.0 - 1.9) / 0.8 - 0.5 < h.now_s < 5.0 + (9.5 - 1.0 - 1.9) / 0.8 + 0.5
    assert h.run_to_end(5) == "success" and any(e.kind == "say" for e in h.events)


def test_if_picks_the_branch_from_what_the_lidar_sees():
    """Facing east down the 10 m corridor nothing is within 1 m ahead; turned round, the west end wall is 0.85 m
    from the footprint. (The first wait lets the first scans come: before any, the condition is unknown.)"""
    h = MissionHarness.from_yaml("""mission: t
tasks:
  look_ahead:
    - if: {obstacle_within: 1 m, sector_deg: [-30, 30]}
      then: [{say: wall ahead}]
      else: [{say: clear ahead}]
steps:
  - wait: 0.5 s
  - do: look_ahead
  - turn: {angle: 180 deg}
  - wait: 0.5 s
  - do: look_ahead
""", world=CORRIDOR)
    assert h.run_to_end(60) == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["clear ahead", "wall ahead"]


def test_a_lidar_that_falls_silent_stops_nothing_blind_the_guard_waits_and_the_drive_fails_as_blocked():
    """The LiDAR goes silent 3 s into the v3 drive: the condition is unknown (said once), the collision monitor
    holds the robot, and the drive fails as blocked after its 5 s without progress; the until never fired."""
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - until: {obstacle_within: 0.6 m}\n    steps:\n"
                                 "      - drive: {distance: 10 m}\n", world=CORRIDOR)
    h.tick_until(lambda h: h.now_s >= 3.0)
    sim = h.run.io.sim
    sim.emulators.remove(next(e for e in sim.emulators if type(e.__self__).__name__ == "SimLd19"))
    x = h.truth.x
    assert h.run_to_end(30) == "failure"
    said = [e for e in h.events if e.kind == "obstacle_within"]
    assert len(said) == 1 and 3.25 < said[0].time_s <= 3.45 and "do not hold (nor does their 'not')" in said[0].text
    assert not any(e.kind == "guard" for e in h.events)
    end = [e.text for e in h.events if e.kind == "mission_end"][0]
    assert "drive 10 m: blocked: no progress for 5 s" in end
    assert h.truth.x - x < 0.15  # held within a few scan periods of the silence


def test_the_docs_obstacle_example_runs_on_the_simulator():
    doc = (REPO / "docs" / "mission-language.md").read_text(encoding="utf-8")
    text = re.search(r"```yaml\n(mission: up_to_the_wall\n.*?)```", doc, re.S).group(1)
    h = MissionHarness.from_yaml(text, base_dir=REPO / "docs")
    assert h.run_to_end(120) == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["wall ahead, turning round"]
    assert h.summary()["truth"]["collisions"] == 0 and h.truth.x < 7.0  # turned round and drove 3 m back west
