"""What ``beastbt tree`` and ``validate`` load at start-up, and the collector pause they run in.

``beastbt tree`` compiles a mission without running it: the tick loop, the
robot's ports, the simulator's world and the teleop wiring stay unloaded (each
is imported where a run is assembled). benchmarks/startup.py measures the time;
this guards what a stray top-level import would bring back.
"""

from __future__ import annotations

import gc
import json
import subprocess
import sys

import pytest

from beastbt.cli import collector_paused
from conftest import REPO

LOADED = """
import json, sys
from beastbt.cli import main
import contextlib, io
with contextlib.redirect_stdout(io.StringIO()):
    status = main(sys.argv[1:])
print(json.dumps({"status": status, "modules": sorted(sys.modules)}))
"""


def _loaded(*words: str) -> tuple[int, set[str]]:
    out = subprocess.run([sys.executable, "-c", LOADED, *words], cwd=REPO, capture_output=True, text=True,
                         check=True, timeout=60)
    result = json.loads(out.stdout.splitlines()[-1])
    return result["status"], set(result["modules"])


def test_tree_loads_no_tick_loop_ports_world_or_teleop_wiring() -> None:
    status, modules = _loaded("tree", "missions/patrol.yaml")
    assert status == 0
    assert "beastbt.mission.compile" in modules and "py_trees" in modules  # it did compile
    for module in ("beastbt.run.runner", "beastbt.run.safety", "beastbt.robot.robot_io", "beastbt.sim.world",
                   "beastbt.actuation.teleop", "beastbt.devices.joystick", "beastbt.behaviours.follow_line",
                   "difflib", "xml.etree.ElementTree", "numpy"):
        assert module not in modules, module


def test_collector_paused_pauses_and_restores() -> None:
    assert gc.isenabled()
    with collector_paused():
        assert not gc.isenabled()
    assert gc.isenabled()
    with pytest.raises(RuntimeError):
        with collector_paused():
            raise RuntimeError("boom")
    assert gc.isenabled()


def test_collector_paused_leaves_a_disabled_collector_disabled() -> None:
    gc.disable()
    try:
        with collector_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()
    finally:
        gc.enable()


FROZEN = """
import contextlib, gc, io, sys
from beastbt.cli import main
sys.argv = ["beastbt", *sys.argv[1:]]
with contextlib.redirect_stdout(io.StringIO()):
    status = main() if sys.argv[1] != "--with-argv" else main(sys.argv[2:])
print(status, gc.get_freeze_count() > 0, gc.isenabled())
"""


@pytest.mark.parametrize("words, frozen", [
    (["tree", "missions/patrol.yaml"], True),  # the command of the process: nothing left for the exit's collection
    (["validate", "missions/patrol.yaml"], True),
    (["--with-argv", "tree", "missions/patrol.yaml"], False),  # main(argv), as the tests call it: the process goes on
    (["runs", "--runs-dir", "no-such-folder"], False),  # not a load-only command
])
def test_a_load_only_command_freezes_what_it_loaded_when_it_is_the_process(words: list[str], frozen: bool) -> None:
    out = subprocess.run([sys.executable, "-c", FROZEN, *words], cwd=REPO, capture_output=True, text=True,
                         check=True, timeout=60)
    status, was_frozen, enabled = out.stdout.split()
    assert was_frozen == str(frozen) and enabled == "True"
    assert status == "0" or words[0] == "runs"
