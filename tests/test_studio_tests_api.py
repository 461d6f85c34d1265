"""The studio's Test button by its API (docs/studio.md, Test): the folder's ``*.test.yaml`` that name the open mission,
run by ``beastbt test`` in a process that takes one of the tries' slots, each file x seed's result; "New test".
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from beastbt.studio.trial import MAX_RUNS
from beastbt.testing.spec import load_test
from test_studio_api import Studio

SHORT = "mission: short\nsteps:\n  - drive: {distance: 0.5 m}\n"
PASSING = "test: short drives half a metre\nmission: ../missions/short.yaml\nseeds: 2\nmax_time: 1 min\n" \
          "expect:\n  status: success\n"
FAILING = "test: short should fail (it does not)\nmission: ../missions/short.yaml\nseeds: [3]\nmax_time: 1 min\n" \
          "expect:\n  status: failure\n"
OTHER = "test: another mission's\nmission: ../missions/other.yaml\nexpect:\n  status: success\n"


@pytest.fixture
def studio(tmp_path: Path):
    (tmp_path / "missions").mkdir()
    (tmp_path / "tests").mkdir()
    (tmp_path / "missions" / "short.yaml").write_text(SHORT, encoding="utf-8")
    (tmp_path / "missions" / "other.yaml").write_text(SHORT.replace("short", "other"), encoding="utf-8")
    (tmp_path / "tests" / "short.test.yaml").write_text(PASSING, encoding="utf-8")
    (tmp_path / "tests" / "short_fails.test.yaml").write_text(FAILING, encoding="utf-8")
    (tmp_path / "tests" / "other.test.yaml").write_text(OTHER, encoding="utf-8")
    s = Studio(tmp_path)
    yield s
    s.server.close()


def test_the_tests_of_a_mission_are_those_whose_mission_is_its_file(studio):
    status, answer = studio.get("/api/tests?path=missions/short.yaml")
    assert status == 200 and answer["tests"] == ["tests/short.test.yaml", "tests/short_fails.test.yaml"]
    assert studio.get("/api/tests?path=missions/other.yaml")[1]["tests"] == ["tests/other.test.yaml"]
    assert studio.get("/api/tests")[0] == 400
    assert studio.get("/api/tests?path=../outside.yaml")[0] in (403, 404)


def test_test_runs_each_file_and_seed_and_says_the_first_failure(studio):
    status, started = studio.post("/api/test", {"path": "missions/short.yaml"})
    assert status == 200, started
    assert started["files"] == ["tests/short.test.yaml", "tests/short_fails.test.yaml"]
    deadline = time.monotonic() + 300
    state = studio.get(f"/api/test/{started['test_id']}")[1]
    while state["state"] == "running" and time.monotonic() < deadline:
        time.sleep(0.5)
        state = studio.get(f"/api/test/{started['test_id']}")[1]
    assert state["state"] == "ended" and state["exit_code"] == 1, state["output"]
    by = {(r["file"], r["seed"]): r for r in state["results"]}
    assert sorted(by) == [("tests/short.test.yaml", 1), ("tests/short.test.yaml", 2),
                          ("tests/short_fails.test.yaml", 3)], state["results"]
    assert by[("tests/short.test.yaml", 1)]["passed"] and by[("tests/short.test.yaml", 2)]["passed"]
    failed = by[("tests/short_fails.test.yaml", 3)]
    assert not failed["passed"] and "seed 3" in failed["message"] and "status" in failed["message"] \
        and "success" in failed["message"], failed
    assert failed["test"] == "short should fail (it does not)"
    # the runs are the folder's: beastbt runs there lists them
    assert len([p for p in (studio.folder / "runs").iterdir() if p.is_dir()]) == 3


def test_a_test_run_takes_one_of_the_tries_slots(studio):
    trials = studio.server.trials
    for _ in range(MAX_RUNS):
        trials.take_slot("try")
    try:
        status, answer = studio.post("/api/test", {"path": "missions/short.yaml"})
        assert status == 409 and f"at most {MAX_RUNS} at once" in answer["error"]
        assert studio.post("/api/try", {"text": SHORT})[0] == 409
    finally:
        for _ in range(MAX_RUNS):
            trials.give_slot()
    assert studio.post("/api/test", {"path": "missions/none.yaml"})[0] == 404  # no test names it


def test_new_test_writes_a_test_file_for_the_mission_that_validates(studio):
    status, made = studio.post("/api/tests/new", {"path": "missions/other.yaml"})
    assert status == 409 and "tests/other.test.yaml exists already" in made["error"]
    assert made["path"] == "tests/other.test.yaml"  # the page opens it instead
    (studio.folder / "missions" / "fresh.yaml").write_text(SHORT.replace("short", "fresh"), encoding="utf-8")
    status, made = studio.post("/api/tests/new", {"path": "missions/fresh.yaml"})
    assert status == 200 and made["path"] == "tests/fresh.test.yaml"
    on_disk = (studio.folder / "tests" / "fresh.test.yaml").read_text(encoding="utf-8")
    assert on_disk == made["text"] and "mission: ../missions/fresh.yaml" in on_disk
    test = load_test(studio.folder / "tests" / "fresh.test.yaml")  # it validates, and names the mission
    assert test.mission.resolve() == (studio.folder / "missions" / "fresh.yaml").resolve()
    assert studio.post("/api/validate", {"text": on_disk, "path": made["path"]})[1] == {"problems": []}
    assert studio.get("/api/tests?path=missions/fresh.yaml")[1]["tests"] == ["tests/fresh.test.yaml"]
    files = {f["path"]: f["kind"] for f in studio.get("/api/files")[1]["files"]}
    assert files["tests/fresh.test.yaml"] == "test"
    # a test file's mistakes are positioned problems in the studio, as beastbt validate says them
    broken = on_disk.replace("status: success", "status: sucess")
    problems = studio.post("/api/validate", {"text": broken, "path": made["path"]})[1]["problems"]
    assert problems and problems[0]["severity"] == "error" and problems[0]["line"] == broken.splitlines().index(
        "  status: sucess") + 1
    assert studio.post("/api/tests/new", {"path": "missions/nothing.yaml"})[0] == 404


def test_a_test_run_ends_with_the_studio(tmp_path):
    """SIGTERM to ``beastbt studio`` (as a service manager ends it) ends its test runs too: none outlives it."""
    import http.client
    import json
    import os
    import subprocess
    import sys
    from conftest import REPO
    from test_studio_api import _alive, _children
    (tmp_path / "missions").mkdir()
    (tmp_path / "tests").mkdir()
    (tmp_path / "missions" / "long.yaml").write_text("mission: long\nsteps:\n  - wait: 3000 s\n", encoding="utf-8")
    (tmp_path / "tests" / "long.test.yaml").write_text(
        "test: long waits\nmission: ../missions/long.yaml\nseeds: 5\nmax_time: 1 h\nexpect:\n  status: success\n",
        encoding="utf-8")
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt", "studio", str(tmp_path), "--listen", "127.0.0.1:0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    started: list[int] = []
    try:
        assert proc.stdout is not None
        url = [proc.stdout.readline() for _ in range(2)][1].split()[-1]
        conn = http.client.HTTPConnection("127.0.0.1", int(url.rsplit(":", 1)[1].strip("/")), timeout=30)
        conn.request("POST", "/api/test", body=json.dumps({"path": "missions/long.yaml"}),
                     headers={"Content-Type": "application/json"})
        answer = conn.getresponse()
        assert answer.status == 200, answer.read()
        conn.close()
        started = _children(proc.pid)
        assert started  # beastbt test
    finally:
        proc.terminate()
        assert proc.wait(30) == 0
    deadline = time.monotonic() + 10
    while [pid for pid in started if _alive(pid)] and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [pid for pid in started if _alive(pid)], "a test run outlived the studio"
