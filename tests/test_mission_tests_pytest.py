"""The pytest plugin: each ``*.test.yaml`` x seed is a test item; a failure says the expectation, the seed and the
value; an invalid file is a collection error at its line. beastbt is not installed here, so the plugin is loaded
by name (``-p``) in a pytest of its own, over a folder of its own (an installed beastbt loads it by its
``pytest11`` entry point, checked in pyproject.toml)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from conftest import REPO

MISSION = f"""\
mission: drive_corridor
world: {REPO / "worlds" / "corridor.yaml"}
steps:
  - drive: {{distance: 3 m, speed: 0.2 m/s}}
"""


def pytest_in(folder: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "beastbt.testing.pytest_plugin",
                           "-p", "no:cacheprovider", "-rA", *args], cwd=folder, capture_output=True, text=True,
                          timeout=600, env=env)


def test_each_file_and_seed_is_a_test_item_and_a_failure_says_which_expectation_seed_and_value(tmp_path):
    (tmp_path / "m.yaml").write_text(MISSION, encoding="utf-8")
    (tmp_path / "good.test.yaml").write_text("test: drives 3 m\nmission: m.yaml\nseeds: [1, 5]\n"
                                             "expect: {status: success, collisions: 0}\n", encoding="utf-8")
    (tmp_path / "bad.test.yaml").write_text("test: wrongly fast\nmission: m.yaml\nseeds: [2]\n"
                                            "expect: {time: '<= 3 s'}\n", encoding="utf-8")
    done = pytest_in(tmp_path, ".")
    out = done.stdout
    assert done.returncode == 1, out + done.stderr
    assert "PASSED good.test.yaml::seed 1" in out and "PASSED good.test.yaml::seed 5" in out, out
    assert re.search(r"FAILED bad.test.yaml::seed 2 - seed 2: expect.time: wanted '<= 3 s', saw \d", out), out
    assert "1 failed, 2 passed" in out
    assert not (tmp_path / "runs").exists()  # pytest records nothing unless asked


def test_an_invalid_file_is_a_collection_error_at_its_line(tmp_path):
    (tmp_path / "m.yaml").write_text(MISSION, encoding="utf-8")
    (tmp_path / "x.test.yaml").write_text("test: x\nmission: m.yaml\nseeds: lots\n", encoding="utf-8")
    done = pytest_in(tmp_path, ".")
    assert done.returncode == 2, done.stdout
    assert f"{tmp_path / 'x.test.yaml'}:3:8: error: expected a whole number in 'seeds'" in done.stdout, done.stdout
    assert "Traceback" not in done.stdout


def test_the_plugin_is_registered_as_a_pytest11_entry_point_and_the_repos_own_pytest_stays_in_tests():
    text = (REPO / "pyproject.toml").read_text(encoding="utf-8")
    entry = re.search(r'^\[project\.entry-points\.pytest11\]\n(.*?)\n', text, re.M).group(1)
    assert entry == 'beastbt = "beastbt.testing.pytest_plugin"'
    assert re.search(r'^testpaths = \["tests"\]', text, re.M)  # missions/tests/*.test.yaml are not collected twice
    assert not list((REPO / "tests").rglob("*.test.yaml"))


def test_loading_the_plugin_imports_no_run_nor_simulator():
    """Every pytest session of a team with beastbt installed loads the plugin: it must cost nearly nothing."""
    code = ("import sys, beastbt.testing.pytest_plugin; "
            "print(sorted(m for m in ('py_trees', 'numpy', 'beastbt.run.runner', 'beastbt.sim.robot') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert done.stdout.strip() == "[]", done.stdout + done.stderr
