"""``beastbt replay``: the recorded sensor streams through the estimator and the tree, commands compared.

A deterministic simulated run replays with no difference, command by
command (mission, mux, gate, servos); a changed mission shows where it
would have acted differently.
"""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from beastbt.cli import main
from beastbt.recording.reader import read_recording
from beastbt.replay import replay
from beastbt.assembly import prepare
from beastbt.run.session import RunOptions, execute
from recording_support import GPS_ROUTE, PATROL, REPO, shared_run


@pytest.fixture(scope="module")
def patrol_run():
    """A recorded patrol: 40 s, drives, looks around (servos), turns."""
    return shared_run("patrol")


def test_a_simulated_patrol_replays_with_no_difference(patrol_run):
    folder, summary = patrol_run
    result = replay(str(folder))
    assert result.identical, [d.describe() for d in result.differences[:5]]
    assert result.ticks == summary["ticks"] and result.differing_ticks == 0
    # The replay really re-decided every command: its servo commands and tree match as well.
    assert read_recording(folder / "run.mcap").topic("/cmd/servo")


def test_a_changed_mission_shows_where_the_commands_differ(patrol_run, tmp_path):
    folder, _ = patrol_run
    text = PATROL.read_text(encoding="utf-8").replace("speed: 0.15 m/s", "speed: 0.1 m/s")
    text = text.replace("../worlds/corridor.yaml", str(PATROL.parent.parent / "worlds" / "corridor.yaml"))
    changed = tmp_path / "slower.yaml"
    changed.write_text(text, encoding="utf-8")
    result = replay(str(folder), mission_path=str(changed))
    assert not result.identical
    first = result.differences[0]
    assert first.tick == 0 and first.stage == "mission"
    assert "0.1500 m/s" in first.recorded and "0.1000 m/s" in first.replayed
    assert 0 < result.differing_ticks <= result.ticks


def test_replay_command_exit_status(patrol_run, tmp_path, capsys):
    folder, _ = patrol_run
    assert main(["replay", str(folder)]) == 0
    assert "no difference" in capsys.readouterr().out
    assert main(["replay", str(tmp_path / "nothing_here")]) == 2


def test_teleop_with_a_joystick_replays_exactly():
    folder, summary = shared_run("teleop")
    rec = read_recording(folder / "run.mcap")
    assert rec.topic("/cmd/teleop") and rec.topic("/sensors/joystick")
    result = replay(str(folder))
    assert result.identical, [d.describe() for d in result.differences[:5]]
    assert result.replay_status == summary["status"] == "success"


@pytest.mark.skipif(not GPS_ROUTE.exists(), reason="no GPS route example yet")
def test_a_gps_route_with_the_ekf_replays_exactly():
    folder, summary = shared_run("gps")
    rec = read_recording(folder / "run.mcap")
    if not rec.topic("/sensors/gps"):
        pytest.skip("the simulated robot has no GPS in this version")
    # The estimator fuses only the IMU device's samples, once its gyro bias is final: the readings' sources
    # and that state are recorded too.
    result = replay(str(folder))
    assert result.identical, [d.describe() for d in result.differences[:5]]
    assert result.ticks == summary["ticks"]


def test_a_recording_cut_short_replays_what_it_holds(patrol_run, tmp_path):
    folder, summary = patrol_run
    data = (folder / "run.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    result = replay(str(cut))
    assert result.identical and 0 < result.ticks < summary["ticks"]
    assert result.truncated_recording and any("cut short" in n for n in result.notes)


def test_a_file_that_is_not_a_recording_is_refused(tmp_path):
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"not an mcap file at all")
    assert main(["replay", str(bad)]) == 2
    assert main(["report", str(bad)]) == 2
    empty_dir = tmp_path / "empty"
    empty_dir.mkdir()
    assert main(["replay", str(empty_dir)]) == 2
    assert Path(bad).exists()


def test_a_camera_run_with_a_snapshot_replays_exactly():
    folder, summary = shared_run("camera")
    result = replay(str(folder))
    assert result.identical, [d.describe() for d in result.differences[:5]]
    assert result.replay_status == summary["status"] == "success"


def test_replay_uses_the_recorded_mission_and_profile_even_when_the_files_changed(tmp_path):
    profile = tmp_path / "my_robot.yaml"
    profile.write_text((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"), encoding="utf-8")
    mission = tmp_path / "m.yaml"
    mission.write_text("mission: m\nsteps:\n  - drive: {distance: 1 m, speed: 0.2 m/s}\n  - turn: {angle: 90 deg}\n",
                       encoding="utf-8")
    p = prepare(str(mission), RunOptions(robot=str(profile), seed=1, runs_dir=str(tmp_path / "runs"),
                                         simulate=True))
    summary = execute(p, io.StringIO())
    assert summary["status"] == "success"
    # Both files change after the run: a slower robot, another mission.
    text = profile.read_text(encoding="utf-8")
    assert "max_speed_mps: 0.35" in text
    profile.write_text(text.replace("max_speed_mps: 0.35", "max_speed_mps: 0.05"), encoding="utf-8")
    mission.write_text("mission: m\nsteps:\n  - wait: 1 s\n", encoding="utf-8")
    result = replay(str(p.folder.path))
    assert result.identical, [d.describe() for d in result.differences[:5]]
    assert result.ticks == summary["ticks"]


def test_a_listed_difference_never_prints_two_equal_values():
    from beastbt.replay import command_texts
    base = {"linear_mps": 0.3, "angular_rps": 0.1, "stamp_s": 1.0, "source": "nav", "mux_source": "mission"}
    for other in ({**base, "linear_mps": 0.3 + 1e-9}, {**base, "stamp_s": 1.05}, {**base, "linear_mps": 0.2}):
        recorded, replayed = command_texts(base, other)
        assert recorded != replayed, (recorded, replayed)
    # Float noise is shown with the fewest digits that tell the two apart, not every digit of the float.
    close = command_texts({**base, "linear_mps": 0.15}, {**base, "linear_mps": 0.1 + 0.05})
    assert close[0] != close[1] and "0.15000000000000002" not in close[1] and "0.15000000000000002" in repr(0.1 + 0.05)
    assert command_texts(base, {**base, "linear_mps": 0.2}) == (
        "0.3000 m/s 0.1000 rad/s (nav, mux mission)", "0.2000 m/s 0.1000 rad/s (nav, mux mission)")
