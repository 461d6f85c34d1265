"""The ``localized`` condition and the ``localization_lost`` failsafe, tick by tick against hand-made map poses.

``localized`` holds while ``map_pose.localized`` is true, does not once it is
false, and is unknown (never holds, nor does its ``not``) without a map pose.
``localization_lost: {after: 3 s, then: hold}`` triggers once the robot has
not been localised for 3 s and clears as soon as it is again.
"""

from __future__ import annotations

from pathlib import Path

import py_trees
import pytest

from beastbt.behaviours.conditions import ConditionReader, not_of
from beastbt.behaviours.context import MissionContext
from beastbt.behaviours.localized import localized
from beastbt.blackboard import catalogue
from beastbt.blackboard.types import MapPose
from beastbt.core.clock import SimClock
from beastbt.core.errors import InvalidInput
from beastbt.core.events import EventLog
from beastbt.mission.model import load_mission
from beastbt.robot.profile import load_profile
from beastbt.run.failsafes import FailsafeMonitor, Situation, failsafe_reads

ZERO_COV = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def map_pose(now_s: float, ok: bool) -> MapPose:
    return MapPose(now_s, 1.0, 2.0, 0.0, ZERO_COV, 0.9 if ok else 0.2, ok)


@pytest.fixture
def reader() -> tuple[ConditionReader, py_trees.blackboard.Client]:
    catalogue.reset_blackboard()
    clock = SimClock()
    ctx = MissionContext(clock=clock, events=EventLog(clock), params=load_profile("sim").control)
    return ConditionReader(ctx), catalogue.writer("test", ("map_pose",))


def test_localized_follows_the_map_pose_and_is_unknown_without_one(reader):
    r, board = reader
    assert localized(r) is None and not_of(localized)(r) is None
    board.map_pose = map_pose(0.0, True)
    assert localized(r) is True
    board.map_pose = map_pose(0.1, False)
    assert localized(r) is False and not_of(localized)(r) is True


def write_mission(folder: Path, failsafe: str) -> Path:
    (folder / "m.pgm").write_bytes(b"P5\n4 4\n255\n" + bytes([254]) * 16)
    (folder / "m_map.yaml").write_text("image: m.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n"
                                       "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    path = folder / "mission.yaml"
    path.write_text(f"mission: m\nmap: m_map.yaml\nfailsafes:\n  localization_lost: {failsafe}\n"
                    "steps:\n  - wait_until: localized\n")
    return path


def test_the_failsafe_acts_after_its_delay_and_clears_when_localized_again(tmp_path):
    mission = load_mission(write_mission(tmp_path, "{after: 3 s, then: hold}"))
    assert failsafe_reads(mission) >= {"map_pose"}
    monitor = FailsafeMonitor(mission)

    def check(now_s: float, pose) -> list[str]:
        return [change for _, change in monitor.check(Situation(now_s, 0.0, None, None, None, None, pose))]

    assert check(0.0, None) == []  # no map pose yet: nothing to judge
    assert check(1.0, map_pose(1.0, True)) == []
    assert check(2.0, map_pose(2.0, False)) == []
    assert check(4.9, map_pose(4.9, False)) == []
    assert check(5.0, map_pose(5.0, False)) == ["trigger"]
    assert monitor.holding()
    assert check(6.0, map_pose(6.0, False)) == []
    assert check(6.1, map_pose(6.1, True)) == ["clear"]
    assert check(8.0, map_pose(8.0, False)) == []  # the delay starts again
    assert check(11.0, map_pose(11.0, False)) == ["trigger"]


def test_the_failsafe_defaults_to_3_s(tmp_path):
    mission = load_mission(write_mission(tmp_path, "{then: stop}"))
    assert mission.failsafes[0].params["after_s"] == 3.0


def test_the_failsafe_without_a_map_is_refused_where_it_stands(tmp_path):
    path = tmp_path / "mission.yaml"
    path.write_text("mission: m\nfailsafes:\n  localization_lost: {then: hold}\nsteps:\n  - wait: 1 s\n")
    with pytest.raises(InvalidInput) as exc:
        load_mission(path)
    assert exc.value.problems[0].position.line == 3 and "no 'map:'" in exc.value.problems[0].message


def test_the_mission_keeps_start_and_initial_uncertainty_in_si_units(tmp_path):
    path = write_mission(tmp_path, "{then: hold}")
    path.write_text(path.read_text().replace("map: m_map.yaml\n", "map: m_map.yaml\nstart: {x: 150 cm, y: -2 m, "
                                             "yaw: 90 deg}\ninitial_uncertainty: {xy: 50 cm, yaw: 30 deg}\n"))
    mission = load_mission(path)
    assert mission.map_start == pytest.approx((1.5, -2.0, 1.5707963))
    assert mission.initial_uncertainty_xy_m == pytest.approx(0.5)
    assert mission.initial_uncertainty_yaw_rad == pytest.approx(0.5235988)
    assert mission.map_grid is not None and mission.map_grid.cols == 4


def test_a_bad_map_file_is_named_at_its_own_line(tmp_path):
    path = write_mission(tmp_path, "{then: hold}")
    (tmp_path / "m_map.yaml").write_text("image: m.pgm\nresolution: -1\n")
    with pytest.raises(InvalidInput) as exc:
        load_mission(path)
    problem = exc.value.problems[0]
    assert problem.file.endswith("m_map.yaml") and problem.position.line == 2


@pytest.mark.parametrize("steps", ["  - wait_until: localized\n",
                                   "  - abort_if: {not: localized}\n    steps:\n      - wait: 1 s\n",
                                   "  - if: {all: [gps_fix, localized]}\n    then:\n      - wait: 1 s\n"])
def test_the_condition_without_a_map_is_refused_where_it_stands(tmp_path, steps):
    path = tmp_path / "mission.yaml"
    path.write_text("mission: m\nsteps:\n" + steps)
    with pytest.raises(InvalidInput) as exc:
        load_mission(path)
    problem = exc.value.problems[0]
    assert problem.position.line >= 3 and "'localized'" in problem.message


def test_a_start_naming_no_place_is_refused(tmp_path):
    path = write_mission(tmp_path, "{then: hold}")
    path.write_text(path.read_text().replace("map: m_map.yaml\n", "map: m_map.yaml\nstart: kitchen\n"))
    with pytest.raises(InvalidInput) as exc:
        load_mission(path)
    assert exc.value.problems[0].position.line == 3 and "kitchen" in exc.value.problems[0].message
