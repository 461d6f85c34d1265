"""The pytest plugin: each ``*.test.yaml`` x seed is a test item; a failure says the expectation, the seed and the
value; an invalid file is a collection error at its line. beastbt is not installed here: the plugin is loaded by name
(``-p``) in a pytest of its own, over a folder of its own; and by its ``pytest11`` entry point, through a dist-info
made from pyproject.toml's, as pip would install it."""

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


def entry_point() -> tuple[str, str]:
    """The ``pytest11`` entry point pyproject.toml declares: (name, module)."""
    text = (REPO / "pyproject.toml").read_text(encoding="utf-8")
    line = re.search(r'^\[project\.entry-points\.pytest11\]\n(?:#.*\n)*(.*?)\n', text, re.M).group(1)
    name, module = (part.strip().strip('"') for part in line.split("=", 1))
    return name, module


def installed(site: Path) -> Path:
    """A folder that makes Python see beastbt as installed with pyproject's pytest11 entry point (a dist-info with
    its entry_points.txt, as pip writes it), for pytest to load the plugin as it would on a team's machine."""
    info = site / "beastbt-0.0.dist-info"
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: beastbt\nVersion: 0.0\n", encoding="utf-8")
    name, module = entry_point()
    (info / "entry_points.txt").write_text(f"[pytest11]\n{name} = {module}\n", encoding="utf-8")
    return site


def pytest_in(folder: Path, *args: str, site: Path = None) -> subprocess.CompletedProcess:
    """pytest in ``folder``: with the plugin by name (``-p``), or, given ``site``, loaded by its entry point."""
    path = str(REPO) if site is None else f"{REPO}{os.pathsep}{site}"
    load = [] if site is not None else ["-p", "beastbt.testing.pytest_plugin"]
    return subprocess.run([sys.executable, "-m", "pytest", *load, "-p", "no:cacheprovider", "-rA", *args],
                          cwd=folder, capture_output=True, text=True, timeout=600, env=dict(os.environ, PYTHONPATH=path))


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


def test_installed_the_plugin_loads_by_its_entry_point_alone_and_with_p_once(tmp_path):
    (tmp_path / "m.yaml").write_text(MISSION, encoding="utf-8")
    (tmp_path / "t.test.yaml").write_text("test: drives\nmission: m.yaml\n", encoding="utf-8")
    site = installed(tmp_path / "site")
    alone = pytest_in(tmp_path, ".", site=site)
    assert alone.returncode == 0 and "PASSED t.test.yaml::seed 1" in alone.stdout, alone.stdout + alone.stderr
    both = pytest_in(tmp_path, "-p", "beastbt.testing.pytest_plugin", ".", site=site)  # as docs/testing.md says
    assert both.returncode == 0 and "1 passed" in both.stdout, both.stdout + both.stderr


def test_the_repos_own_pytest_stays_in_tests():
    text = (REPO / "pyproject.toml").read_text(encoding="utf-8")
    assert re.search(r'^testpaths = \["tests"\]', text, re.M)  # missions/tests/*.test.yaml are not collected twice
    assert not list((REPO / "tests").rglob("*.test.yaml"))


def test_loading_the_plugin_imports_no_run_nor_simulator():
    """Every pytest session of a team with beastbt installed loads the plugin: it must cost nearly nothing."""
    code = ("import sys, beastbt.testing.pytest_plugin; "
            "print(sorted(m for m in ('py_trees', 'numpy', 'beastbt.run.runner', 'beastbt.sim.robot') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert done.stdout.strip() == "[]", done.stdout + done.stderr
