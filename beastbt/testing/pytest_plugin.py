"""pytest collects mission tests: each ``*.test.yaml`` x seed is a test item, so a team's ``pytest`` runs them too.

Installed with beastbt (entry point ``pytest11``: ``beastbt = beastbt.testing.pytest_plugin``); without the
install, ``pytest -p beastbt.testing.pytest_plugin``. Each item runs its seed as ``beastbt test`` does
(:func:`beastbt.testing.runs.run_seed`) and fails with every failed expectation in words, the seed and the
run folder. An invalid test file is a collection error at its line and column.

Options: ``--mission-seeds N`` runs seeds 1..N of every test; ``--mission-runs-dir DIR`` records every run
there (by default pytest records none, so a test session leaves no run folders behind).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator, Optional

import pytest

from beastbt.testing.spec import SUFFIX


def pytest_addoption(parser: Any) -> None:
    """The plugin's options."""
    group = parser.getgroup("beastbt", "beastbt mission tests (*.test.yaml)")
    group.addoption("--mission-seeds", type=int, default=None, metavar="N",
                    help="run seeds 1..N of every mission test instead of its own seeds:")
    group.addoption("--mission-runs-dir", default=None, metavar="DIR",
                    help="record every mission test's run in DIR (default: none recorded)")


def pytest_collect_file(file_path: Path, parent: Any) -> Optional["MissionTestFile"]:
    """A ``*.test.yaml`` file is a file of mission tests."""
    if file_path.name.endswith(SUFFIX):
        return MissionTestFile.from_parent(parent, path=file_path)
    return None


class InvalidMissionTest(Exception):
    """A test file with problems: the positioned problems' text."""


class MissionTestFile(pytest.File):
    """One test file: one item per seed."""

    def collect(self) -> Iterator["MissionTestItem"]:
        """Load and check the file (a problem is a collection error at its line), then one item per seed."""
        from beastbt.core.errors import InvalidInput
        from beastbt.testing.spec import load_test
        try:
            test = load_test(self.path, self.config.getoption("mission_seeds"))
        except InvalidInput as exc:
            raise self.CollectError(exc.format()) from None
        for seed in test.seeds:
            yield MissionTestItem.from_parent(self, name=f"seed {seed}", test=test, seed=seed)


class MissionTestFailed(Exception):
    """A seed whose run did not meet the test's expectations (or could not be made)."""

    def __init__(self, result: Any) -> None:
        super().__init__(result.message())
        self.result = result


class MissionTestItem(pytest.Item):
    """One test file on one seed."""

    def __init__(self, *, test: Any, seed: int, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.test = test
        self.seed = seed

    def runtest(self) -> None:
        """Run the seed; raise :class:`MissionTestFailed` when an expectation does not hold."""
        from beastbt.testing.runs import run_seed
        runs_dir = self.config.getoption("mission_runs_dir")
        result = run_seed(self.test, self.seed, record=runs_dir is not None, runs_dir=runs_dir or "runs")
        if not result.passed:
            raise MissionTestFailed(result)

    def repr_failure(self, excinfo: Any, style: Any = None) -> str:
        """The failed expectations in words (no traceback: the run, not the code, is what failed)."""
        if isinstance(excinfo.value, MissionTestFailed):  # the first line is pytest's short summary of it
            return f"{excinfo.value.result.message()}\n({self.test.name}: {self.path})"
        return super().repr_failure(excinfo)

    def reportinfo(self) -> tuple[Path, int, str]:
        """Where the item is: the test file, and its name with the seed."""
        return self.path, 0, f"{self.test.name} [seed {self.seed}]"


__all__ = ["MissionTestFile", "MissionTestItem", "MissionTestFailed"]
