"""Mission test files (``*.test.yaml``): each event and a substitution change the run as they say; a test that
should fail fails naming the expectation, the seed and the value; an invalid file is a positioned error (exit 2).

The missions here are short (seconds of simulated time) so that each run takes a second or two.
"""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from beastbt.core.errors import InvalidInput
from beastbt.testing.runs import run_seed
from beastbt.testing.spec import load_test
from conftest import REPO

CORRIDOR = REPO / "worlds" / "corridor.yaml"
CAMPUS = REPO / "worlds" / "campus.yaml"

DRIVE = f"""\
mission: drive_corridor
world: {CORRIDOR}
steps:
  - drive: {{distance: 3 m, speed: 0.2 m/s}}
failsafes:
  battery_low: {{below: 11 V, for: 1 s, then: stop}}
"""

GPS = f"""\
mission: gps_hold
world: {CAMPUS}
steps:
  - wait: 20 s
failsafes:
  gps_lost: {{after: 2 s, then: hold}}
"""

GOTO = f"""\
mission: go_a
world: {CAMPUS}
places:
  a: {{lat: 40.41690, lon: -3.70380}}
steps:
  - go_to: a
  - wait: 5 s
"""


def write(folder: Path, mission: str, test: str, name: str = "t.test.yaml") -> Path:
    (folder / "m.yaml").write_text(mission, encoding="utf-8")
    path = folder / name
    path.write_text(test, encoding="utf-8")
    return path


def events_of(folder: Path, mission: str, test: str) -> tuple[object, list[tuple[str, str]]]:
    from beastbt.testing.runs import UnpacedWall, faults_of
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute
    import io
    t = load_test(write(folder, mission, test))
    p = prepare(str(t.mission), RunOptions(seed=1, max_time_s=t.max_time_s, record=False, answers=t.answers),
                faults=faults_of(t))
    summary = execute(p, io.StringIO(), wall=UnpacedWall())
    return (p, summary), [(e["kind"], e["text"]) for e in summary["events"]]


def has(events: list[tuple[str, str]], kind: str, text: str) -> bool:
    return any(k == kind and text in t for k, t in events)


# -- each kind of event changes the run as it says -----------------------------------------------------------

def test_a_gps_dropout_fires_the_missions_gps_lost_failsafe(tmp_path):
    (_, summary), events = events_of(tmp_path, GPS, "test: t\nmission: m.yaml\nevents: [{at: 5 s, gps: lost, for: 6 s}]\n")
    assert has(events, "failsafe", "gps_lost triggered"), events
    assert has(events, "failsafe", "gps_lost cleared"), events
    assert has(events, "test", "GPS lost for 6 s (at 5 s")
    (_, _), calm = events_of(tmp_path, GPS, "test: t\nmission: m.yaml\n")
    assert not has(calm, "failsafe", "gps_lost")  # without the event, the GPS never drops


def test_a_gps_jump_moves_the_receivers_fixes(tmp_path):
    test = "test: t\nmission: m.yaml\nevents: [{at: 5 s, gps: {jump: 25 m}, for: 10 s}]\n"
    (_, jumped), events = events_of(tmp_path, GOTO, test)
    assert has(events, "test", "GPS jumps 25 m for 10 s (at 5 s")
    # The receiver's fixes against the truth: about 3 m RMS on this seed without the jump (the campus's open sky);
    # 10 s of fixes 25 m off among ~50 lift it well above 5 m.
    assert jumped["truth"]["gps_error_rms_m"] > 5.0


def test_a_person_is_seen_by_the_lidar_and_stops_the_robot(tmp_path):
    person = ("test: t\nmission: m.yaml\nmax_time: 30 s\n"
              "events: [{at: 1 s, person: {from: [7, 0], to: [1.5, 0], speed: 1 m/s, gives_way: false}}]\n")
    (_, summary), events = events_of(tmp_path, DRIVE, person)
    assert has(events, "collision_monitor", "stop (mission's command)"), events
    assert summary["truth"]["min_clearance_m"] < 0.5
    (_, calm), calm_events = events_of(tmp_path, DRIVE, "test: t\nmission: m.yaml\n")
    assert not has(calm_events, "collision_monitor", "stop (")
    assert calm["status"] == "success"


def test_a_silent_lidar_holds_the_robot_through_the_collision_monitor(tmp_path):
    (_, _), events = events_of(tmp_path, DRIVE, "test: t\nmission: m.yaml\nevents: [{at: 2 s, lidar: silent, for: 1 s}]\n")
    assert has(events, "collision_monitor", "LiDAR silent, no scan for"), events
    assert has(events, "lidar_back", "scans again")


def test_a_low_battery_fires_the_battery_failsafe(tmp_path):
    (_, summary), events = events_of(tmp_path, DRIVE, "test: t\nmission: m.yaml\nevents: [{at: 2 s, battery: 20 %}]\n")
    assert has(events, "failsafe", "battery_low triggered"), events
    assert summary["status"] == "failure"


def test_an_operator_pause_holds_the_mission_through_the_console_and_resumes_it(tmp_path):
    (_, paused), events = events_of(tmp_path, DRIVE, "test: t\nmission: m.yaml\nevents: [{at: 2 s, operator: pause, for: 5 s}]\n")
    (_, calm), _ = events_of(tmp_path, DRIVE, "test: t\nmission: m.yaml\n")
    assert has(events, "pause", "paused by the operator console") and has(events, "pause", "resumed by the operator console")
    assert paused["status"] == "success"
    assert paused["sim_time_s"] >= calm["sim_time_s"] + 4.5


def test_an_estop_and_an_abort_stop_the_run(tmp_path):
    (_, stopped), events = events_of(tmp_path, DRIVE, "test: t\nmission: m.yaml\nevents: [{at: 2 s, estop: true}]\n")
    assert stopped["status"] == "stopped" and has(events, "estop", "operator console")
    (_, aborted), _ = events_of(tmp_path, DRIVE, "test: t\nmission: m.yaml\nevents: [{at: 2 s, operator: abort}]\n")
    assert aborted["status"] == "stopped"
    assert has([(e["kind"], e["text"]) for e in aborted["events"]], "mission_end", "aborted by the operator console")


def test_an_event_near_a_place_fires_when_the_robot_gets_there(tmp_path):
    (_, summary), events = events_of(tmp_path, GOTO, "test: t\nmission: m.yaml\n"
                                                        "events: [{when: {near: a, within: 4 m}, estop: true}]\n")
    fired = [t for k, t in events if k == "test"]
    assert fired and "near a within 4 m" in fired[0]
    assert summary["status"] == "stopped"
    assert summary["test_events"][0]["time_s"] > 20  # not at the start: the robot had 11 m to go


def test_a_substituted_step_is_named_as_such_in_the_tree_and_forces_its_result(tmp_path):
    test = 'test: t\nmission: m.yaml\nsubstitute:\n  "drive 3 m at 0.2 m/s": {result: failure, after: 2 s}\n'
    (prepared, summary), events = events_of(tmp_path, DRIVE, test)
    names = [n.name for n in prepared.run.root.iterate()]
    assert "drive 3 m at 0.2 m/s [substituted: failure after 2 s]" in names
    assert summary["status"] == "failure"
    assert has(events, "substitute", "drive 3 m at 0.2 m/s: failure (substituted by the test)")
    assert summary["substituted"] == [{"step": "drive 3 m at 0.2 m/s", "result": "failure", "after_s": 2.0}]
    assert summary["distance_m"] == 0.0  # the stand-in stands still
    from beastbt.core.schema_check import validator_for
    assert not list(validator_for("summary.schema.json").iter_errors(summary))


# -- expectations ------------------------------------------------------------------------------------------

def test_expectations_that_hold_pass_and_each_that_does_not_says_which_seed_and_what_it_saw(tmp_path):
    good = run_seed(load_test(write(tmp_path, DRIVE, "test: t\nmission: m.yaml\nexpect:\n  status: success\n"
                                                     "  collisions: 0\n  min_clearance: '>= 0.5 m'\n  time: '<= 30 s'\n")),
                    3, record=False)
    assert good.passed, good.message()
    bad = run_seed(load_test(write(tmp_path, DRIVE, "test: t\nmission: m.yaml\nexpect:\n  status: failure\n"
                                                    "  time: '<= 5 s'\n  events: [{kind: failsafe}]\n")), 3, record=False)
    words = [f.words() for f in bad.failures]
    assert words[0].startswith("expect.status: wanted failure, saw success"), words
    assert words[1].startswith("expect.time: wanted '<= 5 s', saw 1"), words
    assert words[2] == "expect.events[0]: wanted a failsafe event, saw no failsafe event"
    assert bad.first_failure().startswith("seed 3: expect.status")


# -- invalid files -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("test, where, words", [
    ("test: t\nmission: m.yaml\nexpect: {statuss: success}\n", ":3:10:", "unknown key 'statuss'"),
    ("test: t\nmission: m.yaml\nevents:\n  - {at: 2 s, gps: lost, battery: 20 %}\n", ":4:5:",
     "an event has one thing that happens, not 2"),
    ("test: t\nmission: m.yaml\nevents:\n  - {when: {near: gate}, estop: true}\n", ":4:19:", "no place 'gate'"),
    ("test: t\nmission: m.yaml\nsubstitute:\n  drive 3 m: {result: failure}\n", ":4:3:",
     "the mission's tree has no step 'drive 3 m'"),
    ("test: t\nmission: nowhere.yaml\n", ":2:10:", "no file 'nowhere.yaml'"),
    ("test: t\nmission: m.yaml\nevents: [{at: 2 s, estop: true, for: 3 s}]\n", ":3:", "does not last"),
])
def test_an_invalid_test_file_is_a_positioned_error(tmp_path, test, where, words):
    path = write(tmp_path, DRIVE, test)
    with pytest.raises(InvalidInput) as caught:
        load_test(path)
    said = caught.value.format()
    assert f"{path}{where}" in said and words in said, said


# -- the command -------------------------------------------------------------------------------------------

def beastbt(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "beastbt", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600)


def test_beastbt_test_exits_2_on_an_invalid_file_positioned_without_a_traceback(tmp_path):
    write(tmp_path, DRIVE, "test: t\nmission: m.yaml\nseeds: many\n", name="bad.test.yaml")
    done = beastbt("test", str(tmp_path), "--no-record", "--junit", "out.xml", cwd=tmp_path)
    assert done.returncode == 2, done
    assert f"{tmp_path / 'bad.test.yaml'}:3:8: error:" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr + done.stdout
    error = ET.parse(tmp_path / "out.xml").getroot().find("testsuite/testcase/error")  # CI shows it too
    assert error is not None and error.get("message").startswith(f"{tmp_path / 'bad.test.yaml'}:3:8: error:")


def test_beastbt_test_runs_every_file_and_seed_says_the_first_failure_and_writes_junit(tmp_path):
    write(tmp_path, DRIVE, "test: drives 3 m\nmission: m.yaml\nseeds: 2\nexpect: {status: success}\n",
          name="good.test.yaml")
    (tmp_path / "bad.test.yaml").write_text("test: wrongly expects a failure\nmission: m.yaml\nseeds: [4]\n"
                                            "expect: {status: failure}\n", encoding="utf-8")
    done = beastbt("test", "-j", "2", "--junit", "out.xml", cwd=tmp_path)
    assert done.returncode == 1, done
    out = done.stdout
    assert "FAIL  bad.test.yaml: wrongly expects a failure (0/1 seeds: 4 FAIL)" in out, out
    assert "seed 4: expect.status: wanted failure, saw success" in out, out
    assert "PASS  good.test.yaml: drives 3 m (2/2 seeds: 1 ok, 2 ok)" in out, out
    assert "2 tests: 1 passed, 1 failed (2/3 seeds passed)" in out, out
    folder = out.split("(run: ", 1)[1].split(")", 1)[0]
    assert (tmp_path / folder / "summary.json").is_file()  # the failure names its run folder, which report opens
    root = ET.parse(tmp_path / "out.xml").getroot()
    assert root.tag == "testsuites" and root.get("tests") == "3" and root.get("failures") == "1"
    cases = root.findall("testsuite/testcase")
    assert len(cases) == 3 and all(c.get("classname") and c.get("name") and c.get("time") for c in cases)
    failures = [c.find("failure") for c in cases if c.find("failure") is not None]
    assert len(failures) == 1 and "seed 4: expect.status: wanted failure, saw success" in failures[0].get("message")
    passing = beastbt("test", "good.test.yaml", "--seeds", "1", "--no-record", cwd=tmp_path)
    assert passing.returncode == 0 and "(1/1 seeds: 1 ok)" in passing.stdout, passing
    assert not (tmp_path / "runs").exists() or len(list((tmp_path / "runs").iterdir())) == 3


# -- the harness: the same events and substitutions --------------------------------------------------------

def test_the_harness_injects_a_gps_dropout_through_the_same_code(tmp_path):
    from beastbt.testing import MissionHarness
    h = MissionHarness.from_yaml(GPS, base_dir=tmp_path)
    assert h.tick_until(lambda h: h.now_s >= 4.0, timeout_s=10)
    h.inject(gps="lost", for_s=6)
    assert h.tick_until(lambda h: any(e.kind == "failsafe" and "gps_lost triggered" in e.text for e in h.events),
                        timeout_s=5)
    assert h.run.paused_by is not None and h.run.paused_by.startswith("hold")  # the mission's 'then: hold'
    fired = [e.text for e in h.events if e.kind == "test"]
    assert len(fired) == 1 and fired[0].startswith("GPS lost for 6 s (at 4") and fired[0].endswith("events[0])")
    with pytest.raises(ValueError, match="give it in events="):
        h.inject(person={"from": [1, 1], "to": [2, 2]})
    with pytest.raises(InvalidInput, match="'lots' is not allowed"):
        h.inject(gps="lots")


def test_the_harness_takes_substitutions_and_events_as_a_test_file_does(tmp_path):
    from beastbt.testing import MissionHarness
    h = MissionHarness.from_yaml(DRIVE, base_dir=tmp_path, substitute={"drive 3 m at 0.2 m/s": {"result": "success",
                                                                                                  "after": "1 s"}},
                                 events=[{"at": "0.5 s", "operator": "pause", "for": "2 s"}])
    h.tick()
    assert h.status_of("drive 3 m at 0.2 m/s [substituted: success after 1 s]") == "RUNNING"
    assert h.run_to_end(timeout_s=10) == "success"
    assert 2.5 <= h.now_s <= 3.5  # paused 2 s by the console's control, then the stand-in's last 0.5 s
    with pytest.raises(KeyError, match="no step named 'drive 9 m'"):
        MissionHarness.from_yaml(DRIVE, base_dir=tmp_path, substitute={"drive 9 m": {"result": "failure"}})


def test_never_in_reads_the_fences_the_true_position_entered(tmp_path):
    # A keep-out box 2.5-3.5 m east of the corridor's datum, across the corridor: the 3 m drive from x 1 m crosses it.
    box = ("fences:\n  box:\n    keep: out\n    polygon:\n"
           "      - {lat: 40.4167955, lon: -3.7037705}\n      - {lat: 40.4167955, lon: -3.7037587}\n"
           "      - {lat: 40.4168045, lon: -3.7037587}\n      - {lat: 40.4168045, lon: -3.7037705}\n")
    test = "test: t\nmission: m.yaml\nexpect: {never_in: [box]}\n"
    crossed = run_seed(load_test(write(tmp_path, DRIVE + box, test)), 1, record=False)
    assert [f.words() for f in crossed.failures] == ["expect.never_in: wanted never in ['box'], saw entered ['box']"]
    short = DRIVE.replace("distance: 3 m", "distance: 1 m") + box  # stops at x 2 m, short of the box
    assert run_seed(load_test(write(tmp_path, short, test)), 1, record=False).passed


def test_every_shipped_mission_has_a_valid_test_file_naming_its_schema():
    """``beastbt test missions/`` runs one test per shipped mission (run in full by CI and docs/testing.md; here
    each file is only loaded and checked, which is what would make it exit 2)."""
    missions = sorted(p.name for p in (REPO / "missions").glob("*.yaml"))
    tests = sorted((REPO / "missions" / "tests").glob("*.test.yaml"))
    assert sorted(load_test(t).mission.name for t in tests) == missions
    for t in tests:
        first = t.read_text(encoding="utf-8").splitlines()[0]
        assert first == "# yaml-language-server: $schema=../../schemas/test.schema.json", t


def test_beastbt_validate_checks_a_test_file_as_a_test(tmp_path, capsys):
    from beastbt import cli
    assert cli.main(["validate", str(REPO / "missions" / "tests" / "patrol.test.yaml")]) == 0
    bad = write(tmp_path, DRIVE, "test: t\nmission: m.yaml\nexpect: {reached: [gate]}\n")
    assert cli.main(["validate", str(bad)]) == 2
    assert f"{bad}:3:20: error: the mission has no place 'gate'" in capsys.readouterr().err


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_sigterm_stops_the_whole_test_session_not_only_the_run_under_way(tmp_path, jobs):
    import signal
    import time
    slow = DRIVE.replace("distance: 3 m, speed: 0.2 m/s", "distance: 9 m, speed: 0.01 m/s")  # 15 min of mission
    write(tmp_path, slow, "test: slow\nmission: m.yaml\nseeds: 4\n")
    process = subprocess.Popen([sys.executable, "-m", "beastbt", "test", "-j", jobs], cwd=tmp_path, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while not (tmp_path / "runs").is_dir() and time.monotonic() < deadline:
            time.sleep(0.1)  # a run has started (its folder is made before it moves)
        time.sleep(1.0)
        process.send_signal(signal.SIGTERM)
        out, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, out + err
    assert "interrupted after 0 of 4 runs" in err, err
    assert "Traceback" not in err


ASK = """\
mission: door_check
steps:
  - ask: {id: door, question: Is the door open?, timeout: 5 s, default: no}
    then:
      - drive: {distance: 1 m}
    else:
      - say: "door closed, staying"
"""


def test_answers_are_given_as_the_question_opens_and_asked_reads_the_ask_events(tmp_path):
    test = "test: t\nmission: m.yaml\nanswers: {door: yes}\nexpect: {asked: [door], status: success}\n"
    answered = run_seed(load_test(write(tmp_path, ASK, test)), 1, record=False)
    assert answered.passed, answered.message()
    unanswered = run_seed(load_test(write(tmp_path, ASK, "test: t\nmission: m.yaml\nexpect: {time: '< 5 s'}\n")), 1,
                          record=False)  # nobody answers: the question waits its 5 s timeout
    assert [f.name for f in unanswered.failures] == ["time"]
    with pytest.raises(InvalidInput, match="the mission asks no question 'window'"):
        load_test(write(tmp_path, ASK, "test: t\nmission: m.yaml\nanswers: {window: yes}\n"))


def test_a_recorded_test_run_replays_identically_substitution_pause_and_person_included(tmp_path):
    from beastbt.replay import replay
    test = ("test: t\nmission: m.yaml\nevents:\n  - {at: 0.5 s, operator: pause, for: 1 s}\n"
            "  - {at: 0.2 s, person: {from: [3, 0.6], to: [3, -0.6], speed: 0.5 m/s}}\n"
            'substitute:\n  "drive 3 m at 0.2 m/s": {result: failure, after: 3 s}\n')
    result = run_seed(load_test(write(tmp_path, DRIVE, test)), 1, record=True, runs_dir=str(tmp_path / "runs"))
    assert result.status == "failure" and result.folder is not None
    replayed = replay(result.folder)
    assert replayed.identical, [d for d in replayed.differences[:3]]
    assert replayed.replay_status == "failure"


def test_robot_takes_a_bundled_profiles_name_or_a_file_and_says_where_a_wrong_one_is(tmp_path):
    assert load_test(write(tmp_path, DRIVE, "test: t\nmission: m.yaml\nrobot: ugv_beast\n")).robot == "ugv_beast"
    with pytest.raises(InvalidInput) as caught:
        load_test(write(tmp_path, DRIVE, "test: t\nmission: m.yaml\nrobot: ugv_beest\n"))
    said = caught.value.format()
    assert f"{tmp_path / 't.test.yaml'}:3:8: error: no robot profile called 'ugv_beest'; did you mean 'ugv_beast'?" in said, said


def test_an_event_cannot_wait_for_a_place_on_a_map(tmp_path):
    test = tmp_path / "o.test.yaml"
    test.write_text(f"test: t\nmission: {REPO / 'missions' / 'office_rooms.yaml'}\n"
                    "events: [{when: {near: kitchen}, estop: true}]\n", encoding="utf-8")
    with pytest.raises(InvalidInput) as caught:
        load_test(test)
    assert f"{test}:3:24: error: 'kitchen' is a place on the mission's map" in caught.value.format()


def test_the_search_skips_hidden_folders_and_finds_each_file_once(tmp_path):
    from beastbt.testing.spec import find_tests
    for folder in ("a", "a/b", ".venv/lib", "node_modules/x"):
        (tmp_path / folder).mkdir(parents=True, exist_ok=True)
        (tmp_path / folder / "t.test.yaml").write_text("test: t\n", encoding="utf-8")
    (tmp_path / "a" / "m.yaml").write_text("mission: m\n", encoding="utf-8")
    found = find_tests([tmp_path, tmp_path / "a", tmp_path / "a" / "b" / "t.test.yaml"])
    assert found == [tmp_path / "a" / "t.test.yaml", tmp_path / "a" / "b" / "t.test.yaml"]


def test_two_runs_making_their_folder_in_the_same_second_get_two_folders(tmp_path, monkeypatch):
    """beastbt test -j N starts runs of one mission at once: the one that finds its folder made takes the next."""
    import datetime
    from beastbt.core.clock import SimClock
    from beastbt.run.run_folder import RunFolder
    when = lambda: datetime.datetime(2026, 12, 6, 23, 0, 0, tzinfo=datetime.timezone.utc)  # noqa: E731
    first = RunFolder.create(str(tmp_path), "m", SimClock(), calendar=when)
    monkeypatch.setattr(Path, "exists", lambda self: False)  # as if the other process made it after the look
    second = RunFolder.create(str(tmp_path), "m", SimClock(), calendar=when)
    assert first.path != second.path and second.path.name.endswith("-2")
