"""One mission test on one seed: assembled with its faults, run as fast as the machine allows, checked.

:func:`run_seed` is what ``beastbt test``, the pytest plugin and the studio
call: it prepares the run as ``beastbt run`` does (:func:`beastbt.assembly.prepare`,
with the test's :class:`~beastbt.testing.faults.TestFaults`), executes it
through :func:`beastbt.run.session.execute` (so the run folder, recording
and summary are those of any run), and checks the summary
(:mod:`beastbt.testing.expectations`). Times are seconds.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from typing import Optional

from beastbt.core.clock import WallClock
from beastbt.testing.expectations import Failure, check
from beastbt.testing.faults import TestFaults
from beastbt.testing.spec import MissionTest


class UnpacedWall(WallClock):
    """Wall time that never waits: a test runs at full speed even while its operator pauses the mission.

    An ordinary run at ``--speed max`` slows to real time during an operator's pause (a person is waiting);
    in a test the pause is scripted and nobody waits, so the run goes on as fast as it can. ``now`` is the
    true wall time, so ``wall_time_s`` stays true.
    """

    def sleep_until(self, t_s: float) -> None:
        """Return at once."""


@dataclass
class SeedResult:
    """The outcome of one test file on one seed: ``status`` the run's (or ``error`` when it could not run),
    the expectations that failed, the run folder (None when not recorded), the wall time (s), and ``error``:
    why the run could not be made (a positioned problem's text)."""

    test: str
    file: str
    seed: int
    status: str
    failures: list[Failure] = field(default_factory=list)
    folder: Optional[str] = None
    wall_s: float = 0.0
    error: Optional[str] = None
    invalid: bool = False
    """True when ``error`` is the user's input (a bad world, profile or mission): ``beastbt test`` exits 2."""

    @property
    def passed(self) -> bool:
        """True when the run was made and every expectation held."""
        return self.error is None and not self.failures

    def first_failure(self) -> str:
        """The first failure in words, with the seed (and the run folder), or ``""`` when it passed."""
        if self.error is not None:
            return f"seed {self.seed}: {self.error}"
        if not self.failures:
            return ""
        where = f" (run: {self.folder})" if self.folder else ""
        return f"seed {self.seed}: {self.failures[0].words()}{where}"

    def message(self) -> str:
        """Every failure in words, one a line, with the seed and the run folder."""
        if self.error is not None:
            return f"seed {self.seed}: {self.error}"
        lines = [f"seed {self.seed}: {f.words()}" for f in self.failures]
        if self.folder:
            lines.append(f"run folder: {self.folder} (beastbt report {self.folder}; beastbt replay {self.folder})")
        return "\n".join(lines)


def faults_of(test: MissionTest) -> TestFaults:
    """The faults one run of ``test`` carries out (a fresh set for each run)."""
    return TestFaults(test.events, test.substitutions, test.expect.never_in)


def run_seed(test: MissionTest, seed: int, record: bool = True, runs_dir: str = "runs") -> SeedResult:
    """Run ``test`` on ``seed`` at full speed and check its expectations; never raises for a user's mistake."""
    from beastbt.assembly import prepare
    from beastbt.core.errors import InvalidInput
    from beastbt.robot.hardware import DeviceUnavailable
    from beastbt.run.run_folder import RunFolderUnavailable
    from beastbt.run.session import RunOptions, execute

    result = SeedResult(test.name, str(test.file), seed, "error")
    options = RunOptions(robot=test.robot, world=str(test.world) if test.world else None, seed=seed, speed="max",
                         max_time_s=test.max_time_s, runs_dir=runs_dir, record=record, simulate=True,
                         answers=dict(test.answers))
    wall = UnpacedWall()
    try:
        prepared = prepare(str(test.mission), options, faults=faults_of(test))
    except InvalidInput as exc:
        result.error, result.invalid = exc.format(), True
        return result
    except (DeviceUnavailable, RunFolderUnavailable) as exc:
        result.error, result.invalid = str(exc), True
        return result
    try:
        summary = execute(prepared, io.StringIO(), wall=wall)
    except Exception as exc:  # noqa: BLE001 - a run that broke is this seed's failure, said in a line
        result.error = f"the run broke: {type(exc).__name__}: {exc}"
        result.folder = str(prepared.folder.path) if prepared.folder is not None else None
        return result
    end = next((e["text"] for e in reversed(summary["events"]) if e["kind"] == "mission_end"), "")
    if end.startswith("stopped: interrupted"):
        # Ctrl-C or SIGTERM ended this run (execute turns them into a stop): the whole test session stops too.
        raise KeyboardInterrupt(end)
    result.status = str(summary["status"])
    result.failures = check(test.expect, summary)
    result.wall_s = round(wall.now(), 3)
    if prepared.folder is not None:
        result.folder = str(prepared.folder.path)
        verdict = {"test": test.name, "file": str(test.file), "seed": seed, "passed": result.passed,
                   "failures": [f.words() for f in result.failures]}
        try:  # beside the summary, for whoever opens the folder; the summary is what counts
            (prepared.folder.path / "test.json").write_text(json.dumps(verdict, indent=2) + "\n", encoding="utf-8")
        except OSError:
            pass
    return result


__all__ = ["SeedResult", "run_seed", "faults_of", "UnpacedWall"]
