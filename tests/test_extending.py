"""A package from outside beastbt adds a part and a step through entry points, and a mission uses them.

The fixture package ``tests/fixtures/beastbt_blinker`` (an LED part and a
``blink`` step) is installed for real with pip into a folder of its own; the
CLI then runs in a subprocess that sees it (``PYTHONPATH``), so
``importlib.metadata`` finds its entry points exactly as for an installed
package. ``docs/extending.md`` walks through the same files.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import REPO

FIXTURE = REPO / "tests" / "fixtures" / "beastbt_blinker"

MISSION = """\
mission: blink_and_go
steps:
  - blink: {times: 3, period: 400 ms}
  - drive: {distance: 0.5 m, speed: 0.2 m/s}
"""


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The fixture package installed with pip into a folder of its own; that folder."""
    target = tmp_path_factory.mktemp("site")
    source = tmp_path_factory.mktemp("src") / FIXTURE.name
    shutil.copytree(FIXTURE, source)  # the build leaves its build/ and egg-info there, not in the checkout
    base = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target)]
    done = subprocess.run(base + ["--no-build-isolation", str(source)], capture_output=True, text=True, timeout=300)
    if done.returncode != 0:  # no setuptools in this environment: let pip fetch a build backend
        done = subprocess.run(base + [str(source)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert any(p.name.startswith("beastbt_blinker") and p.name.endswith(".dist-info") for p in target.iterdir())
    return target


def beastbt(args: list[str], cwd: Path, site: Path | None) -> subprocess.CompletedProcess:
    """``python -m beastbt ARGS``; the fixture package is visible when ``site`` is given."""
    paths = ([str(site)] if site is not None else []) + [str(REPO)]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(paths))
    return subprocess.run([sys.executable, "-m", "beastbt", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=120)


def profile_with(tmp_path: Path, parts: dict) -> Path:
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    data["robot"] = "sim_with_parts"
    data["parts"] = parts
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def test_a_mission_uses_a_step_and_a_part_from_another_package(installed, tmp_path):
    mission = tmp_path / "blink.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    robot = profile_with(tmp_path, {"blinker": {"pin": 7}})
    summary = tmp_path / "summary.json"
    done = beastbt(["run", str(mission), "--robot", str(robot), "--sim", "--no-record", "--summary", str(summary)],
                   tmp_path, installed)
    assert done.returncode == 0, done.stdout + done.stderr
    s = json.loads(summary.read_text())
    assert s["status"] == "success" and s["blinker"]["pin"] == 7 and s["blinker"]["blinks"] == 3
    assert s["distance_m"] > 0.45  # the core steps after it ran too
    tree = beastbt(["tree", str(mission), "--robot", str(robot)], tmp_path, installed)
    assert "--> blink 3 times" in tree.stdout, tree.stderr


def test_the_step_is_checked_against_its_own_schema_with_positions(installed, tmp_path):
    mission = tmp_path / "bad.yaml"
    mission.write_text(MISSION.replace("times: 3", "times: 0"), encoding="utf-8")
    done = beastbt(["validate", str(mission)], tmp_path, installed)
    assert done.returncode == 2
    assert re.search(rf"{re.escape(str(mission))}:3:\d+: error: .*times", done.stderr), done.stderr


def test_without_the_package_the_step_is_unknown_and_nothing_runs(tmp_path):
    mission = tmp_path / "blink.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    done = beastbt(["validate", str(mission)], tmp_path, None)
    assert done.returncode == 2
    assert f"{mission}:3:5: error:" in done.stderr and "blink" in done.stderr, done.stderr
    run = beastbt(["run", str(mission)], tmp_path, None)
    assert run.returncode == 2 and not (tmp_path / "runs").exists()


def test_an_unknown_part_is_refused_at_its_line_with_the_installed_names(installed, tmp_path):
    mission = tmp_path / "m.yaml"
    mission.write_text("mission: m\nsteps: [stop]\n", encoding="utf-8")
    robot = profile_with(tmp_path, {"blinkr": {"pin": 7}})
    done = beastbt(["run", str(mission), "--robot", str(robot), "--sim", "--no-record"], tmp_path, installed)
    assert done.returncode == 2
    assert "no part called 'blinkr'" in done.stderr and "blinker" in done.stderr, done.stderr
    line = next(i for i, text in enumerate(robot.read_text().splitlines(), 1) if "blinkr" in text)
    assert f"{robot}:{line}:" in done.stderr


def test_a_part_on_a_real_robot_says_what_to_check(installed, tmp_path):
    mission = tmp_path / "blink.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    data = yaml.safe_load((REPO / "robots" / "ugv_beast.yaml").read_text(encoding="utf-8"))
    data = {k: v for k, v in data.items() if k not in ("gps", "imu", "camera", "lidar", "joystick")}
    master, slave = os.openpty()  # the base's serial port opens; nothing moves before the part refuses
    try:
        data["base"]["port"] = os.ttyname(slave)
        data["parts"] = {"blinker": {"pin": 99}}
        robot = tmp_path / "real.yaml"
        robot.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        done = beastbt(["run", str(mission), "--robot", str(robot), "--no-record"], tmp_path, installed)
    finally:
        os.close(master)
        os.close(slave)
    assert done.returncode == 2 and "GPIO 99 is not exported" in done.stderr, done.stderr


def test_the_walkthrough_shows_the_fixture_files_as_they_are():
    doc = (REPO / "docs" / "extending.md").read_text(encoding="utf-8")
    blocks = dict(re.findall(r"```python title=\"(tests/fixtures/[^\"]+)\"\n(.*?)```", doc, flags=re.S))
    blocks.update(re.findall(r"```toml title=\"(tests/fixtures/[^\"]+)\"\n(.*?)```", doc, flags=re.S))
    assert set(blocks) >= {"tests/fixtures/beastbt_blinker/beastbt_blinker/part.py",
                           "tests/fixtures/beastbt_blinker/beastbt_blinker/step.py",
                           "tests/fixtures/beastbt_blinker/pyproject.toml"}
    for path, text in blocks.items():
        assert (REPO / path).read_text(encoding="utf-8") == text, f"docs/extending.md shows an old {path}"
