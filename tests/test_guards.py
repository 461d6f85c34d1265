"""Guards that interrupt (mission language v2): until / abort_if halt a running drive, follow_line and route
on the very tick their condition first holds; the halted step's terminate runs and nothing commands motion."""

from __future__ import annotations

import py_trees
import pytest

from beastbt.behaviours.flow import GuardedBlock
from beastbt.testing import MissionHarness
from conftest import REPO

Status = py_trees.common.Status
PLACES = "places:\n  a: {lat: 40.41690, lon: -3.70380}\n  b: {lat: 40.41700, lon: -3.70350}\n"


def harness(text: str, world: str) -> MissionHarness:
    return MissionHarness.from_yaml(f"mission: guarded\nworld: {world}\n{text}", base_dir=REPO / "worlds", seed=2)


def guard_of(h: MissionHarness) -> GuardedBlock:
    return next(n for n in h.run.nodes if isinstance(n, GuardedBlock))


def run_until_the_guard_ends(h: MissionHarness, leaf_name: str, timeout_s: float = 120.0):
    """Tick until the guard block is no longer running; the leaf's status on each tick before, and the guard."""
    guard = guard_of(h)
    leaf = h.node(leaf_name)
    seen = []
    while h.now_s < timeout_s:
        h.tick()
        seen.append((h.records[-1], leaf.status))
        if guard.status not in (Status.RUNNING, Status.INVALID) and len(seen) > 1:
            return guard, leaf, seen
    raise AssertionError(f"the guard never ended: {guard.feedback_message}")


def assert_halted_on_that_tick(guard, leaf, seen, expected: Status) -> None:
    last, _ = seen[-1]
    assert guard.status == expected
    assert seen[-2][1] == Status.RUNNING, "the step was running until the condition held"
    assert leaf.status == Status.INVALID, "the running step was halted (its terminate ran)"
    assert last.cmd_mission is None or last.cmd_mission.is_zero(), "nothing commands motion on the halting tick"


def test_until_halts_a_running_drive_on_the_tick_the_time_is_up():
    h = harness("steps:\n  - until: {time_in_block: 2 s}\n    steps:\n      - drive: {distance: 5 m, speed: 0.2 m/s}\n"
                "  - wait: 1 s\n", "corridor.yaml")
    guard, leaf, seen = run_until_the_guard_ends(h, "drive 5 m at 0.2 m/s")
    assert_halted_on_that_tick(guard, leaf, seen, Status.SUCCESS)
    elapsed = seen[-1][0].now_s - guard.block.start_s
    assert 2.0 <= elapsed < 2.0 + h.dt_s + 1e-9, elapsed  # the first tick on which it held
    assert any(e.kind == "guard" and "halting drive 5 m" in e.text for e in h.events)
    assert h.run_to_end(30) == "success"  # until succeeds: the mission goes on


def test_abort_if_halts_a_running_follow_line_on_the_tick_the_distance_is_reached():
    h = harness("steps:\n  - abort_if: {distance_travelled: 0.8 m}\n    steps:\n"
                "      - follow_line: {speed: 0.12 m/s, until: intersection}\n", "line_track.yaml")
    guard, leaf, seen = run_until_the_guard_ends(h, "follow line until intersection at 0.12 m/s")
    assert_halted_on_that_tick(guard, leaf, seen, Status.FAILURE)
    start = guard.block.start_distance_m
    travelled = [r.pose_odom.distance_m - start for r, _ in seen]
    assert travelled[-1] >= 0.8 > travelled[-2]  # halted on the first tick it held
    assert h.run_to_end(5) == "failure"
    assert "distance travelled 0.8 m holds, halting follow line" in h.summary()["events"][-1]["text"]


def test_until_halts_a_running_route_on_the_tick_the_time_is_up():
    h = harness(PLACES + "steps:\n  - until: {time_in_block: 15 s}\n    steps:\n      - route: {places: [a, b]}\n",
                "campus.yaml")
    guard, leaf, seen = run_until_the_guard_ends(h, guard_of(h).body.children[0].name)
    assert_halted_on_that_tick(guard, leaf, seen, Status.SUCCESS)
    assert 15.0 <= seen[-1][0].now_s - guard.block.start_s < 15.0 + h.dt_s + 1e-9


def test_when_the_steps_end_first_the_block_ends_as_they_did():
    done = harness("steps:\n  - until: {time_in_block: 1 h}\n    steps:\n      - wait: 1 s\n", "corridor.yaml")
    assert done.run_to_end(30) == "success"
    failed = harness("steps:\n  - abort_if: {time_in_block: 1 h}\n    steps:\n      - go_to: nowhere_known\n"
                     "places:\n  nowhere_known: {lat: 40.41690, lon: -3.70380}\n", "corridor.yaml")
    assert failed.run_to_end(120) == "failure"
    assert not any(e.kind == "guard" for e in failed.events)


@pytest.mark.parametrize("text", [
    "steps:\n  - until: {distance_travelled: -1 m}\n    steps: [wait: 1 s]\n",
    "steps:\n  - abort_if: {time_in_block: 0 s}\n    steps: [wait: 1 s]\n",
])
def test_guard_amounts_must_be_positive(text):
    from beastbt.core.errors import InvalidInput
    with pytest.raises(InvalidInput, match="must be greater than zero"):
        harness(text, "corridor.yaml")


def test_the_docs_guard_example_runs():
    import re
    doc = (REPO / "docs" / "mission-language.md").read_text(encoding="utf-8")
    text = re.search(r"```yaml\n(mission: guarded_corridor.*?)```", doc, re.S).group(1)
    h = MissionHarness.from_yaml(text, base_dir=REPO / "docs", seed=1)
    assert h.run_to_end(120) == "success"
    assert any(e.kind == "guard" and "distance travelled 1.5 m holds, halting drive 3 m" in e.text for e in h.events)
    assert h.summary()["distance_m"] == pytest.approx(1.5, abs=0.1)
