"""Mistakes a user can type or write get a clear error, exit 2, and no traceback; nothing starts (issue 15)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

PATROL = str(REPO / "missions" / "patrol.yaml")


def beastbt(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "beastbt", *args], capture_output=True, text=True, timeout=120,
                          cwd=cwd, env=dict(os.environ, PYTHONPATH=str(REPO)))


def nested(levels: int) -> str:
    text, indent = "mission: deep\nsteps:\n", "  "
    for _ in range(levels):
        text += f"{indent}- repeat:\n{indent}    times: 1\n{indent}    steps:\n"
        indent += "      "
    return text + f"{indent}- wait: 1 s\n"


@pytest.mark.parametrize("levels", [80, 400])
def test_a_mission_nested_too_deeply_is_refused_with_its_position(tmp_path, levels):
    path = tmp_path / "deep.yaml"
    path.write_text(nested(levels))
    done = beastbt("validate", str(path))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert f"{path}:" in done.stderr and "nested too deeply" in done.stderr and "tasks:" in done.stderr


def test_a_mission_nested_within_the_limit_runs(tmp_path):
    path = tmp_path / "ok.yaml"
    path.write_text(nested(25))
    done = beastbt("run", str(path), "--no-record")
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("args, says", [
    (["tree", PATROL, "--dot", "/nonexistent-folder/tree.dot"], "the folder /nonexistent-folder does not exist"),
    (["run", PATROL, "--no-record", "--summary", "/nonexistent-folder/s.json"], "the folder /nonexistent-folder"),
    (["run", PATROL, "--no-record", "--record", "/nonexistent-folder/r.mcap"], "the folder /nonexistent-folder"),
    (["run", PATROL, "--record-images", "-1"], "is negative"),
    (["run", PATROL, "--seed", "-5"], "is negative"),
    (["run", PATROL, "--max-time", "0"], "not a positive duration"),
    (["run", PATROL, "--max-time", "-5 s"], "not a positive duration"),
    (["run", PATROL, "--stream-quality", "0"], "JPEG quality 1-100"),
])
def test_bad_options_exit_2_before_anything_starts(tmp_path, args, says):
    done = beastbt(*args, cwd=tmp_path)
    assert done.returncode == 2, done.stdout + done.stderr
    assert says in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "runs").exists() and "mission_start" not in done.stdout


def test_runs_dir_that_is_a_file(tmp_path):
    (tmp_path / "runs").write_text("not a folder")
    done = beastbt("run", PATROL, "--runs-dir", str(tmp_path / "runs"), cwd=tmp_path)
    assert done.returncode == 2 and "is a file, not a folder" in done.stderr and "Traceback" not in done.stderr


def test_yaml_merge_keys_work(tmp_path):
    path = tmp_path / "merge.yaml"
    path.write_text("mission: merged\nsteps:\n  - drive: &slow {distance: 1 m, speed: 0.1 m/s}\n"
                    "  - drive:\n      <<: *slow\n      distance: 0.5 m\n")
    done = beastbt("run", str(path), "--no-record", "--summary", str(tmp_path / "s.json"))
    assert done.returncode == 0, done.stderr
    import json
    assert json.loads((tmp_path / "s.json").read_text())["distance_m"] == pytest.approx(1.5, abs=0.1)
    twice = tmp_path / "twice.yaml"
    twice.write_text("mission: t\nsteps:\n  - drive: {distance: 1 m, distance: 2 m}\n")
    done = beastbt("validate", str(twice))
    assert done.returncode == 2 and "duplicate key 'distance'" in done.stderr


def test_a_mission_named_with_accents_runs_and_its_folder_names_file_and_mission(tmp_path):
    path = tmp_path / "tour.yaml"
    path.write_text("mission: café_straße\nsteps:\n  - wait: 1 s\n")
    done = beastbt("run", str(path), "--runs-dir", str(tmp_path / "runs"))
    assert done.returncode == 0, done.stderr
    [folder] = (tmp_path / "runs").iterdir()
    assert folder.name.endswith("_tour_café_straße")
