"""The patrol mission end to end through the CLI: the foundation's contract."""

from __future__ import annotations

import json
import math

from beastbt import cli
from beastbt.mission.model import load_mission
from beastbt.mission.steps import Repeat
from conftest import REPO

PATROL = REPO / "missions" / "patrol.yaml"


def run(tmp_path, seed: int, name: str) -> dict:
    out = tmp_path / name
    code = cli.main(["run", str(PATROL), "--seed", str(seed), "--summary", str(out), "--runs-dir", str(tmp_path / "runs")])
    summary = json.loads(out.read_text())
    summary["exit_code"] = code
    return summary


def test_patrol_succeeds_covers_its_distance_and_looks_both_ways(tmp_path):
    s = run(tmp_path, 1, "s.json")
    assert s["exit_code"] == 0
    assert s["status"] == "success"
    asked = 3 * 2 * 3.0   # repeat 3 times, two 3 m drives per pass
    assert abs(s["distance_m"] - asked) <= 0.05 * asked
    assert {-45.0, 45.0, 0.0} <= set(s["servos"]["pan"])
    assert s["max_speed_mps"] <= 0.3 + 1e-6
    for key in ("mission", "seed", "sim_time_s", "wall_time_s", "ticks", "waypoints", "events"):
        assert key in s
    assert s["mission"] == "corridor_patrol" and s["seed"] == 1
    assert s["ticks"] == round(s["sim_time_s"] * 20) + 1
    assert (tmp_path / "runs").is_dir() and any((tmp_path / "runs").iterdir())


def test_same_seed_same_summary_apart_from_wall_time(tmp_path):
    a, b = run(tmp_path, 7, "a.json"), run(tmp_path, 7, "b.json")
    a.pop("wall_time_s"), b.pop("wall_time_s")
    assert a == b
    c = run(tmp_path, 8, "c.json")
    assert c["truth"]["final_pose"] != a["truth"]["final_pose"]   # the seed does change the noise


def test_patrol_stays_in_the_corridor(tmp_path):
    s = run(tmp_path, 3, "s.json")
    pose = s["truth"]["final_pose"]
    assert 0 < pose["x"] < 10 and -1 < pose["y"] < 1
    assert not s["truth"]["blocked"]


def test_max_time_stops_the_run_with_exit_1(tmp_path, capsys):
    out = tmp_path / "s.json"
    code = cli.main(["run", str(PATROL), "--max-time", "10 s", "--summary", str(out), "--no-record"])
    s = json.loads(out.read_text())
    assert code == 1 and s["status"] == "stopped"
    assert s["sim_time_s"] <= 10.0 + 1e-6
    assert any(e["kind"] == "mission_end" and "max time" in e["text"] for e in s["events"])


def test_the_patrol_is_the_language_docs_example():
    m = load_mission(PATROL)
    assert m.speed_limit_mps == 0.3 and set(m.tasks) == {"look_around"}
    assert isinstance(m.steps[0], Repeat) and m.steps[0].times == 3
    assert [type(s).__name__ for s in m.steps[0].steps] == ["DriveDistance", "Do", "TurnBy"] * 2
    assert math.isclose(m.rate_hz, 20.0)


def test_tree_command_prints_readable_names_and_writes_dot(tmp_path, capsys):
    dot = tmp_path / "t.dot"
    assert cli.main(["tree", str(PATROL), "--dot", str(dot)]) == 0
    out = capsys.readouterr().out
    assert "drive 3 m at 0.15 m/s" in out and "do look_around" in out and "repeat 3 times" in out
    text = dot.read_text()
    assert text.startswith("digraph mission {") and '"turn 180 deg"' in text and "->" in text


def test_summary_matches_its_schema(tmp_path):
    import jsonschema
    from beastbt.core.schema_check import load_schema
    s = run(tmp_path, 2, "s.json")
    s.pop("exit_code")
    jsonschema.validate(s, load_schema("summary.schema.json"))
