"""The studio's Test button: the folder's mission tests (``*.test.yaml``) that name the open mission, run by
``beastbt test --junit`` in a process of its own, and each file x seed's result; and "New test" from a template.

A test names its mission by a path relative to itself (``mission: ../missions/lawn.yaml``): a test file belongs to
the open mission when that path resolves to the mission's file. The run is the command a user or CI types
(``python -m beastbt test FILE ... --junit FILE --runs-dir FOLDER/runs -j 1``), so the studio shows what CI would.
It takes one of the tries' slots (:data:`beastbt.studio.trial.MAX_RUNS` simulator processes at once in all) and
runs its seeds one after the other (``-j 1``): a studio shares its machine. Its runs go to the folder's ``runs/``;
its JUnit XML and printed output to a temporary folder, removed when the studio forgets the test run.
"""

from __future__ import annotations

import os
import secrets
import shutil
import subprocess
import sys
import tempfile
import threading
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from beastbt.studio.files import FileRefused, StudioFolder, refusal_of

OUTPUT_LINES = 200
"""The last lines ``beastbt test`` printed, kept for ``GET /api/test/<id>``."""
KEPT_TEST_RUNS = 10
"""How many ended test runs are remembered."""
TEST_TIMEOUT_S = 1800.0
"""A test run still running after this long (wall s) is stopped: its seeds' own ``max_time`` ends each run first."""

NEW_TEST = """# A test of {mission_name}: `beastbt test {test_path}` runs it on every seed (docs/testing.md).
test: {mission_name} ends in success
mission: {mission_ref}
seeds: 3                    # seeds 1, 2, 3: the simulator's noise differs on each
max_time: 10 min            # of mission time: a run still going then is stopped (and fails)
# events:                   # faults and happenings, by time or by place
#   - {{at: 30 s, gps: lost, for: 10 s}}
expect:
  status: success
  collisions: 0
"""
"""The text "New test" writes: it validates for any mission that validates."""


class TestExists(FileRefused):
    """"New test" for a mission whose ``tests/<mission>.test.yaml`` is there already: a 409 naming it (``path``)."""

    def __init__(self, path: str) -> None:
        super().__init__(409, f"{path} exists already: it is opened instead (copy it to test more)")
        self.path = path


def mission_of_test(test_file: Path) -> Optional[Path]:
    """The mission file a test file names (``mission:``, relative to the test file), resolved; None when it names
    none (not YAML, no ``mission:`` text)."""
    import yaml
    try:
        data = yaml.safe_load(test_file.read_text(encoding="utf-8")[:200_000])
    except (OSError, ValueError, yaml.YAMLError):
        return None
    mission = data.get("mission") if isinstance(data, dict) else None
    if not isinstance(mission, str) or not mission.strip():
        return None
    target = Path(mission.strip())
    return (target if target.is_absolute() else test_file.parent / target).resolve()


def tests_of(folder: StudioFolder, mission_path: str) -> list[str]:
    """The test files in the folder (relative paths, sorted) whose ``mission:`` is the file at ``mission_path``."""
    from beastbt.testing.spec import find_tests
    mission = folder.resolve(mission_path).resolve()
    root = folder.root.resolve()
    found = []
    for test_file in find_tests([folder.root]):
        if "runs" in test_file.resolve().relative_to(root).parts[:-1]:
            continue  # a run folder's copy is no test of the folder's
        if mission_of_test(test_file) == mission:
            found.append(test_file.resolve().relative_to(root).as_posix())
    return sorted(found)


def new_test(folder: StudioFolder, mission_path: str) -> dict:
    """Write ``tests/<mission>.test.yaml`` for the mission at ``mission_path`` from :data:`NEW_TEST`:
    ``{path, text, version}``; FileRefused 409 when that file exists already (its path in the message)."""
    mission = folder.resolve(mission_path)
    if not mission.is_file():
        raise FileRefused(404, f"no mission '{mission_path[:80]}': save it first, then make its test")
    stem = mission.name.removesuffix(".yaml").removesuffix(".yml")
    target_rel = f"tests/{stem}.test.yaml"
    target = folder.resolve(target_rel, must_exist=False)
    if target.exists():
        raise TestExists(target_rel)
    import yaml
    try:
        name = yaml.safe_load(mission.read_text(encoding="utf-8")).get("mission") or stem
    except (OSError, ValueError, AttributeError, yaml.YAMLError):
        name = stem
    text = NEW_TEST.format(mission_name=str(name), test_path=target_rel,
                           mission_ref=Path(os.path.relpath(mission, target.parent)).as_posix())
    version = folder.write(target_rel, text, None)
    return {"path": target_rel, "text": text, "version": version}


@dataclass
class TestRun:
    """One ``beastbt test`` the studio started."""

    test_id: str
    process: subprocess.Popen
    folder: Path
    """Its temporary folder: the JUnit XML."""
    files: list[str]
    output: deque = field(default_factory=lambda: deque(maxlen=OUTPUT_LINES))
    reader: Optional[threading.Thread] = None

    @property
    def junit(self) -> Path:
        """Where ``--junit`` writes."""
        return self.folder / "junit.xml"


def junit_results(path: Path, root: Path) -> list[dict]:
    """Each file x seed of a JUnit XML that ``beastbt test`` wrote: ``{file, test, seed, passed, message}``, in its
    order (``file`` relative to ``root`` when inside it)."""
    import re
    import xml.etree.ElementTree as ET
    results = []
    for suite in ET.parse(path).getroot().iter("testsuite"):
        name = suite.get("name", "")
        try:
            file = Path(name).resolve().relative_to(root.resolve()).as_posix()
        except ValueError:
            file = name
        for case in suite.iter("testcase"):
            bad = case.find("failure")
            if bad is None:
                bad = case.find("error")
            m = re.search(r"\[seed (\d+)\]$", case.get("name", ""))
            results.append({"file": file, "test": re.sub(r" \[seed \d+\]$", "", case.get("name", "")),
                            "seed": int(m.group(1)) if m else None, "passed": bad is None,
                            "message": None if bad is None else (bad.get("message") or bad.text or "").strip()})
    return results


class TestRuns:
    """The test runs the studio started, by id; they share the tries' slots (see the module docstring)."""

    def __init__(self, folder: StudioFolder, trials: Any) -> None:
        self.folder = folder
        self.trials = trials
        self.runs: dict[str, TestRun] = {}
        self._lock = threading.Lock()

    def start(self, mission_path: str) -> dict:
        """Run the tests of the mission at ``mission_path``: ``{test_id, files}``; FileRefused when there is none, or
        every slot is taken."""
        files = tests_of(self.folder, mission_path)
        if not files:
            raise FileRefused(404, f"no test names {mission_path[:80]}: make one with New test (tests/NAME.test.yaml, "
                                   f"docs/testing.md)")
        self.trials.take_slot("test run")
        try:
            return self._start(files)
        except BaseException:
            self.trials.give_slot()
            raise

    def _start(self, files: list[str]) -> dict:
        with self._lock:
            ended = [t for t in self.runs.values() if t.process.poll() is not None]
            for old in ended[:max(0, len(ended) - KEPT_TEST_RUNS)]:
                del self.runs[old.test_id]
                shutil.rmtree(old.folder, ignore_errors=True)
        test_id = secrets.token_hex(6)
        try:
            tmp = Path(tempfile.mkdtemp(prefix=f"beastbt-studio-test-{test_id}-"))
        except OSError as exc:
            raise refusal_of(exc, "the tests did not start") from None
        command = [sys.executable, "-m", "beastbt", "test", *files, "--junit", str(tmp / "junit.xml"),
                   "--runs-dir", str(self.folder.root / "runs"), "-j", "1"]
        try:
            process = subprocess.Popen(command, cwd=self.folder.root, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                       stderr=subprocess.STDOUT, text=True, errors="replace",
                                       env=dict(os.environ, PYTHONUNBUFFERED="1"))
        except OSError:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        run = TestRun(test_id, process, tmp, files)
        with self._lock:
            self.runs[test_id] = run
        run.reader = threading.Thread(target=self._read, args=(run,), name=f"beastbt-test-{test_id}", daemon=True)
        run.reader.start()
        return {"test_id": test_id, "files": files, "state": "running"}

    def _read(self, run: TestRun) -> None:
        assert run.process.stdout is not None
        timer = threading.Timer(TEST_TIMEOUT_S, run.process.terminate)
        timer.daemon = True
        timer.start()
        for line in run.process.stdout:
            run.output.append(line.rstrip("\n"))
        run.process.wait()
        timer.cancel()
        self.trials.give_slot()

    def get(self, test_id: str) -> TestRun:
        """The test run ``test_id``; FileRefused 404 when there is none."""
        run = self.runs.get(test_id)
        if run is None:
            raise FileRefused(404, f"no test run '{test_id[:40]}' (the studio forgets them when it stops)")
        return run

    def state(self, test_id: str) -> dict:
        """``{test_id, state, files, output, exit_code?, results?}``: ``results`` each file x seed once ended."""
        run = self.get(test_id)
        code = run.process.poll()
        out: dict[str, Any] = {"test_id": test_id, "state": "running" if code is None else "ended",
                               "files": run.files, "output": list(run.output)}
        if code is not None:
            if run.reader is not None:
                run.reader.join(2.0)
                out["output"] = list(run.output)
            out["exit_code"] = code
            try:
                out["results"] = junit_results(run.junit, self.folder.root)
            except (OSError, ValueError, SyntaxError):
                out["results"] = []  # exit 2 before any run (an invalid file): its output says why
        return out

    def stop(self, test_id: str) -> dict:
        """End a test run (SIGTERM: the run under way stops and is kept, no other starts) and answer its state."""
        run = self.get(test_id)
        if run.process.poll() is None:
            run.process.terminate()
            try:
                run.process.wait(10.0)
            except subprocess.TimeoutExpired:
                run.process.kill()
                run.process.wait(5.0)
        return self.state(test_id)

    def stop_all(self, wait_s: float = 1.0) -> None:
        """The studio is ending: SIGTERM to every test run, SIGKILL after ``wait_s``; temporary folders removed."""
        runs = list(self.runs.values())
        for run in runs:
            if run.process.poll() is None:
                run.process.terminate()
        for run in runs:
            try:
                run.process.wait(wait_s)
            except subprocess.TimeoutExpired:
                run.process.kill()
            shutil.rmtree(run.folder, ignore_errors=True)


__all__ = ["TestExists", "TestRuns", "TestRun", "junit_results", "mission_of_test", "new_test", "tests_of"]
