"""The studio stays bounded in time, memory, processes and disk, with the hostile probe's inputs (issue 38, points 3
and 4; issue 37, items 10 and 11).

Checks, trees, maps and edits run in worker processes that are killed and replaced when a job takes too long, runs
out of its address space or its client leaves: a text too large is a problem at line 1, not a studio that hangs.
SIGTERM ends a busy studio at once, with its workers and tries, and no try's folder is left in the temporary
folder. At most 4 tries run however many are asked for at once. What the client did wrong is a 4xx, a full disk a
507, each with a message; hidden files are not written.
"""

from __future__ import annotations

import errno
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

import pytest

from conftest import REPO
from test_studio_api import Studio, _alive, _children

SMALL = "mission: m\nsteps:\n  - wait: 1 s\n"
LONG_TRY = "mission: long\nsteps:\n  - wait: 300 s\n"


def many_waits(n: int = 150_000) -> str:
    """A legal mission of ``n`` waits (150,000: 2.1 MB, under the body limit), which takes beastbt tens of seconds
    to check: far longer than the short time limit the tests give the studio."""
    return "mission: many\nsteps:\n" + "  - wait: 1 s\n" * n


def long_list(rows: int = 18_000) -> str:
    """A mission whose description is a list of 60 x ``rows`` numbers (2.2 MB): composing it takes some 300 MB."""
    return "mission: m\nsteps:\n  - wait: 1 s\ndescription: [\n" + ("1," * 60 + "\n") * rows + "1]\n"


def raw_post(port: int, path: str, body: dict) -> socket.socket:
    """Send ``POST path`` with ``body`` and return the open socket, without reading the answer."""
    data = json.dumps(body).encode()
    sock = socket.create_connection(("127.0.0.1", port), timeout=30)
    sock.sendall(f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json\r\n"
                 f"Content-Length: {len(data)}\r\nConnection: close\r\n\r\n".encode() + data)
    return sock


def wait_until(condition, timeout_s: float, step_s: float = 0.1) -> bool:
    """Poll ``condition()`` until it is true or ``timeout_s`` has passed; its last value."""
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(step_s)
    return bool(condition())


def cpu_s(pid: int) -> float:
    """The CPU time ``pid`` has used (s), 0 when it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def warm(studio: Studio) -> None:
    """Wait until both workers answer (they warm up after the studio starts)."""
    assert studio.post("/api/validate", {"text": SMALL})[0] == 200
    assert wait_until(lambda: len(studio.server.pool.pids()) == 2, 30)


@pytest.fixture
def quick(tmp_path) -> Iterator[Studio]:
    """A studio that gives each check 1 s (every text below takes far longer)."""
    (tmp_path / "m.yaml").write_text(SMALL, encoding="utf-8")
    s = Studio(tmp_path, work_timeout_s=1.0)
    yield s
    s.server.close()


def test_a_text_too_large_to_check_in_time_is_a_problem_at_line_1_and_its_worker_is_replaced(quick):
    warm(quick)
    big = many_waits()
    for op, verb, doing in (("validate", "check", "checking"), ("tree", "compile", "compiling"),
                            ("map", "draw", "drawing")):
        before = set(quick.server.pool.pids())
        started = time.monotonic()
        status, answer = quick.post(f"/api/{op}", {"text": big})
        took = time.monotonic() - started
        assert status == 200, answer
        [problem] = answer["problems"]
        assert (problem["line"], problem["column"], problem["severity"]) == (1, 1, "error")
        assert problem["message"] == f"this text is too large to {verb} here: {doing} it took more than 1 s"
        assert "beastbt validate FILE" in problem["hint"]
        assert took < 30  # not the minutes the whole check takes
        # the busy worker was killed, and another one took its place
        assert wait_until(lambda: not all(_alive(p) for p in before), 10), "the busy worker was not killed"
        assert wait_until(lambda: len(quick.server.pool.pids()) == 2 and set(quick.server.pool.pids()) != before,
                          30)
    # an edit of it is a 413 with the same reason
    status, answer = quick.post("/api/edit", {"text": big, "edit": {"op": "add_place", "lat": 40.0, "lon": -3.0}})
    assert status == 413 and answer["error"].startswith("this text is too large to edit here")
    assert (answer["line"], answer["column"]) == (1, 1)
    assert quick.post("/api/validate", {"text": SMALL})[1]["problems"] == []  # and the studio serves on


def test_a_client_that_leaves_frees_its_worker(tmp_path):
    (tmp_path / "m.yaml").write_text(SMALL, encoding="utf-8")
    s = Studio(tmp_path, work_timeout_s=120.0)  # only the client's leaving can end this job
    try:
        warm(s)
        before = set(s.server.pool.pids())
        used = {pid: cpu_s(pid) for pid in before}
        sock = raw_post(s.server.port, "/api/validate", {"text": many_waits()})
        assert wait_until(lambda: any(cpu_s(p) > used[p] + 1.0 for p in before), 60), "no worker took the job"
        assert all(_alive(p) for p in before)
        sock.close()
        assert wait_until(lambda: not all(_alive(p) for p in before), 10), "the worker still checks for nobody"
        assert wait_until(lambda: len(s.server.pool.pids()) == 2, 30)
        assert s.post("/api/validate", {"text": SMALL})[1]["problems"] == []
    finally:
        s.server.close()


def test_a_worker_is_bounded_in_memory_and_a_text_that_needs_more_is_too_large(tmp_path):
    (tmp_path / "m.yaml").write_text(SMALL, encoding="utf-8")
    # the smallest address space a worker takes: what it uses warm plus 64 MB
    s = Studio(tmp_path, work_timeout_s=600.0, work_memory_bytes=0)
    try:
        warm(s)
        for pid in s.server.pool.pids():
            limits = Path(f"/proc/{pid}/limits").read_text()
            soft = re.search(r"Max address space\s+(\S+)", limits).group(1)
            assert soft != "unlimited" and int(soft) < 1 << 30, limits
        sock = raw_post(s.server.port, "/api/validate", {"text": long_list()})
        sock.settimeout(600)  # a loaded machine composes slowly: the limit, not the clock, must end this check
        head, _, body = sock.makefile("rb").read().partition(b"\r\n\r\n")
        sock.close()
        assert head.startswith(b"HTTP/1.1 200"), head
        answer = json.loads(body)
        [problem] = answer["problems"]
        assert problem["line"] == 1 and "too large to check here: checking it needed more than" in \
            problem["message"], problem
        assert wait_until(lambda: len(s.server.pool.pids()) == 2, 30)
        assert s.post("/api/validate", {"text": SMALL})[1]["problems"] == []
    finally:
        s.server.close()


def test_sigterm_ends_a_busy_studio_at_once_with_its_workers_and_tries_and_their_folders(tmp_path):
    folder, temp = tmp_path / "folder", tmp_path / "tmp"
    folder.mkdir()
    temp.mkdir()
    env = dict(os.environ, PYTHONPATH=str(REPO), TMPDIR=str(temp))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt", "studio", str(folder), "--listen", "127.0.0.1:0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    children: list[int] = []
    socks = []
    try:
        assert proc.stdout is not None
        url = [proc.stdout.readline() for _ in range(2)][1].split()[-1]
        studio = Remote(int(url.rsplit(":", 1)[1].strip("/")))
        port = studio.server.port
        assert studio.post("/api/validate", {"text": SMALL})[0] == 200
        status, started = studio.post("/api/try", {"text": LONG_TRY, "speed": "realtime"})
        assert status == 200, started
        assert wait_until(lambda: list(temp.glob("beastbt-studio-try-*")), 30)
        # both workers busy with texts that take minutes, and requests waiting for them
        socks = [raw_post(port, "/api/validate", {"text": many_waits()}) for _ in range(3)]
        time.sleep(2.0)
        children = _children(proc.pid)
        assert len(children) >= 3  # two workers and the try
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(30)
        took = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        for sock in socks:
            sock.close()
    assert code == 0
    assert took < 10, f"the studio took {took:.1f} s to end"  # 2 s on an idle machine; generous for a busy one
    assert wait_until(lambda: not [pid for pid in children if _alive(pid)], 5), "a worker or a try outlived it"
    assert not list(temp.glob("beastbt-studio-try-*")), "a try's folder outlived the studio"
    assert not list(folder.glob(".*.try-*"))


class Remote(Studio):
    """Requests to a studio served by another process, on ``port``."""

    def __init__(self, port: int) -> None:
        self.server = type("Address", (), {"port": port})()


def _beastbt_runs() -> list[int]:
    """This process's children that are a ``beastbt run`` (the tries of an in-process studio)."""
    found = []
    for pid in _children(os.getpid()):
        try:
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"beastbt" in cmdline and b"run" in cmdline and _alive(pid):
            found.append(pid)
    return found


def test_thirty_tries_at_once_start_at_most_four_simulators(tmp_path, monkeypatch):
    (tmp_path / "m.yaml").write_text(SMALL, encoding="utf-8")
    s = Studio(tmp_path)
    popen = subprocess.Popen

    def slow_popen(*args, **kwargs):  # a loaded machine, where starting a process takes a moment
        time.sleep(0.3)
        return popen(*args, **kwargs)

    monkeypatch.setattr(subprocess, "Popen", slow_popen)
    statuses: list[int] = []
    most = [0]
    watching = threading.Event()

    def watch() -> None:
        while not watching.is_set():
            most[0] = max(most[0], len(_beastbt_runs()))
            time.sleep(0.05)

    def ask() -> None:
        statuses.append(s.post("/api/try", {"text": LONG_TRY, "speed": "realtime"})[0])

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        for _ in range(3):  # three running: the next requests race for the last slot
            ask()
        askers = [threading.Thread(target=ask) for _ in range(27)]
        for t in askers:
            t.start()
        for t in askers:
            t.join(120)
        time.sleep(1.0)
        assert sorted(statuses) == [200] * 4 + [409] * 26, statuses
        assert len(_beastbt_runs()) == 4
    finally:
        watching.set()
        watcher.join()
        s.server.close()
    assert most[0] <= 4, f"{most[0]} simulators ran at once"
    assert not _beastbt_runs()


@pytest.fixture(scope="module")
def studio(tmp_path_factory) -> Iterator[Studio]:
    root = tmp_path_factory.mktemp("bounds")
    (root / "missions").mkdir()
    (root / "missions" / "m.yaml").write_text(SMALL, encoding="utf-8")
    s = Studio(root)
    yield s
    s.server.close()


def test_a_name_too_long_is_a_400_with_a_message(studio):
    name = "a" * 300 + ".yaml"
    for method, path, body in (("PUT", f"/api/files/{name}", {"text": SMALL, "version": None}),
                               ("PUT", f"/api/files/missions/{name}", {"text": SMALL, "version": None}),
                               ("GET", f"/api/files/{name}", None),
                               ("POST", "/api/validate", {"text": SMALL, "path": name})):
        status, answer = studio.request(method, path, body)
        assert status == 400, (method, path, answer)
        assert "is a name of 305 bytes: a file or folder name is at most 255" in answer["error"]
    deep = "/".join(["folder"] * 200) + "/m.yaml"
    status, answer = studio.put(f"/api/files/{deep}", {"text": SMALL, "version": None})
    assert status == 400 and "the studio takes paths of at most 1024" in answer["error"]


def test_hidden_files_and_folders_are_not_written(studio):
    for path in (".git/config.yaml", "missions/.hidden.yaml", ".beastbt/m.yaml", "missions/.cache/x.yaml"):
        status, answer = studio.put(f"/api/files/{path}", {"text": SMALL, "version": None})
        assert status == 403 and "is hidden" in answer["error"], (path, answer)
        assert not (studio.folder / path).exists()
        assert not (studio.folder / path).parent.exists() or (studio.folder / path).parent == studio.folder / \
            "missions"


def test_a_full_disk_is_a_507_and_the_file_on_disk_is_kept(studio, monkeypatch):
    path = "missions/full.yaml"
    status, saved = studio.put(f"/api/files/{path}", {"text": SMALL, "version": None})
    assert status == 200

    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)  # the server runs in this process: its saves find the disk full
    status, answer = studio.put(f"/api/files/{path}", {"text": SMALL + "# more\n", "version": saved["version"]})
    assert status == 507 and "the disk is full" in answer["error"], answer
    status, answer = studio.put("/api/files/missions/new.yaml", {"text": SMALL, "version": None})
    assert status == 507 and "the disk is full" in answer["error"], answer
    monkeypatch.undo()
    assert (studio.folder / path).read_text(encoding="utf-8") == SMALL
    assert not [p.name for p in (studio.folder / "missions").iterdir() if p.name.endswith(".tmp")]


def test_an_edit_of_a_flow_nested_50000_deep_is_a_400_where_it_nests(studio):
    deep = "mission: d\nsteps:\n  - " + "[" * 50_000 + "]" * 50_000 + "\n"
    status, answer = studio.post("/api/edit", {"text": deep, "edit": {"op": "add_place", "lat": 40.0,
                                                                     "lon": -3.0}})
    assert status == 400, answer
    assert "nested too deeply" in answer["error"] and answer["line"] == 3 and answer["column"] > 100


def test_the_docs_name_the_fence_the_page_draws_as_the_edit_names_it(studio):
    """The page draws keep-out fences (studio-web/src/main.ts: add_fence with keep: out); docs/studio.md must give
    the name the edit writes for them."""
    page = (REPO / "studio-web" / "src" / "main.ts").read_text(encoding="utf-8")
    assert 'op: "add_fence", keep: "out"' in page
    polygon = [[40.0, -3.0], [40.001, -3.0], [40.001, -3.001]]
    names = {}
    for keep in ("out", "in"):
        names[keep] = studio.post("/api/edit", {"text": SMALL, "edit": {"op": "add_fence", "keep": keep,
                                                                         "polygon": polygon}})[1]["name"]
    docs = (REPO / "docs" / "studio.md").read_text(encoding="utf-8")
    bullet = docs[docs.index('`{op: "add_fence"'):]
    bullet = bullet[:bullet.index("\n- ")]
    assert f"`{names['out']}`" in bullet and f"`{names['in']}`" in bullet, (names, bullet)


def test_the_try_limit_holds_for_starts_at_the_same_moment(tmp_path, monkeypatch):
    """Many starts at once with three tries running (each start slowed, as on a loaded machine): one more starts.
    The HTTP server hands tries to a few threads; here every start has a thread of its own."""
    from beastbt.studio.files import FileRefused, StudioFolder
    from beastbt.studio.trial import Trials
    trials = Trials(StudioFolder(tmp_path))
    popen = subprocess.Popen

    def slow_popen(*args, **kwargs):
        time.sleep(0.3)
        return popen(*args, **kwargs)

    monkeypatch.setattr(subprocess, "Popen", slow_popen)
    outcomes: list[str] = []

    def start() -> None:
        try:
            trials.start(LONG_TRY, None, {"speed": "realtime"})
            outcomes.append("started")
        except FileRefused as exc:
            outcomes.append(str(exc.status))

    try:
        for _ in range(3):
            start()
        starters = [threading.Thread(target=start) for _ in range(27)]
        for t in starters:
            t.start()
        for t in starters:
            t.join(120)
        assert sorted(outcomes) == ["409"] * 26 + ["started"] * 4, outcomes
        assert len(_beastbt_runs()) == 4
    finally:
        trials.stop_all()
    assert not _beastbt_runs()
    assert all(not t.folder.exists() for t in trials.runs.values())
