"""The composition root: explicit parts, each used only when the profile or the run needs it, no registries."""

from __future__ import annotations

import ast
import json
import subprocess
import sys

import pytest

from beastbt.assembly import BASES, BUILTIN_PARTS, assemble, base_part, parts_for, step_builders
from beastbt.blackboard import catalogue
from beastbt.core.clock import SimClock
from beastbt.mission.compile import CORE_STEPS
from beastbt.mission.model import load_mission
from beastbt.parts.teleop import TeleopPart
from beastbt.robot.part import REPLAY, Part
from beastbt.robot.profile import load_profile
from beastbt.robot.robot_io import RobotIO
from beastbt.run.safety import TICK
from beastbt.run.session import RunOptions
from conftest import REPO

ROBOT_SCHEMA = json.loads((REPO / "schemas" / "robot.schema.json").read_text())


def every_part() -> list[Part]:
    """Every built-in part and every base part, imported."""
    return [entry.load() for entry in BUILTIN_PARTS] + [base_part_by_type(t) for t in BASES]


def base_part_by_type(kind: str) -> Part:
    from beastbt.assembly import _import_target, _instantiate
    return _instantiate(_import_target(BASES[kind]), kind)


@pytest.mark.parametrize("part", every_part(), ids=lambda p: p.name)
def test_every_part_describes_itself_truthfully(part):
    assert isinstance(part, Part) and part.name and part.__doc__
    for key in part.fills:
        assert key in catalogue.KEYS, f"{part.name} fills '{key}', which is not a blackboard key"
    if part.section is not None:
        assert part.section in ROBOT_SCHEMA["properties"], f"{part.name}: no '{part.section}' section in the schema"
    if part.schema is not None:
        assert (REPO / "schemas" / part.schema).is_file(), f"{part.name}: {part.schema} does not exist"
    for kind in part.steps():
        assert kind not in CORE_STEPS


def test_a_profile_gets_only_the_parts_it_uses():
    sim = [p.name for p in parts_for(load_profile("sim"), RunOptions())]
    assert {"gps", "imu", "camera", "navigation", "teleop", "recording"} <= set(sim)
    assert "video_stream" not in sim and "joystick" not in sim
    can = [p.name for p in parts_for(load_profile(str(REPO / "robots" / "diy_can.yaml")), RunOptions(record=False))]
    assert "camera" not in can and "gps" not in can and "recording" not in can
    assert base_part(load_profile(str(REPO / "robots" / "diy_can.yaml")), simulated=True).name == "can_base"


def test_a_profile_without_a_camera_never_imports_the_camera_code(tmp_path):
    mission = tmp_path / "m.yaml"
    mission.write_text("mission: t\nsteps:\n  - drive: {distance: 0.2 m}\n")
    code = (f"import sys\nfrom beastbt.assembly import prepare\nfrom beastbt.run.session import RunOptions, execute\n"
            f"p = prepare({str(mission)!r}, RunOptions(robot={str(REPO / 'robots' / 'diy_can.yaml')!r}, simulate=True, "
            f"record=False))\nassert execute(p, open('/dev/null', 'w'))['status'] == 'success'\n"
            f"print(sorted(m for m in sys.modules if m.startswith('beastbt.parts.')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    loaded = out.stdout.strip()
    assert "beastbt.parts.can_base" in loaded
    for unused in ("beastbt.parts.camera", "beastbt.parts.gps", "beastbt.parts.imu", "beastbt.parts.waveshare",
                   "beastbt.parts.video_stream", "beastbt.parts.recording"):
        assert unused not in loaded


def test_only_parts_with_per_tick_work_are_called_each_tick():
    profile = load_profile("sim")
    mission = load_mission("m.yaml", text="mission: t\nsteps: [stop]\n")
    io = RobotIO(base=_NullBase())
    prepared = assemble(mission, profile, RunOptions(record=False), REPLAY, io=io, clock=SimClock(),
                        parts=[p for p in parts_for(profile, RunOptions(record=False)) if p.name != "camera"])
    hooks = prepared.run.hooks
    assert len(hooks) == 1 and getattr(hooks[0], "__self__", None).name == "teleop"
    assert prepared.run.watchdog_checked_by == TICK  # a replayed robot's watchdog is checked every tick


def test_the_core_steps_are_read_only_and_parts_cannot_redefine_them():
    with pytest.raises(TypeError):
        CORE_STEPS["drive"] = None  # type: ignore[index]

    class Bad(Part):
        name = "bad"

        def steps(self):
            return {"drive": lambda c, s: None}

    with pytest.raises(ValueError, match="redefines the core step 'drive'"):
        step_builders([TeleopPart(), Bad()])


MUTATORS = {"append", "extend", "insert", "update", "setdefault", "add", "__setitem__"}


def registrations(source: str, where: str) -> list[str]:
    """Import-time registrations in ``source``: ``@register...`` decorators, and import-time mutations of an
    ALL_CAPS container that is public or defined in another module (a private table a module derives for
    itself, like ``_UNIT_TO_KIND``, is not a registry)."""
    found = []
    tree = ast.parse(source)
    defined = {tg.id for n in tree.body if isinstance(n, (ast.Assign, ast.AnnAssign))
               for tg in (n.targets if isinstance(n, ast.Assign) else [n.target]) if isinstance(tg, ast.Name)}
    for node in tree.body:  # the statements that run at import time
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            for deco in node.decorator_list:
                call = deco.func if isinstance(deco, ast.Call) else deco
                if isinstance(call, ast.Name) and call.id.startswith("register"):
                    found.append(f"{where}:{node.lineno}: @{call.id}")
            continue
        for sub in ast.walk(node):
            target = None
            if isinstance(sub, ast.Call) and isinstance(sub.func, ast.Attribute) and sub.func.attr in MUTATORS:
                target = sub.func.value
            elif isinstance(sub, (ast.Assign, ast.AugAssign)):
                targets = sub.targets if isinstance(sub, ast.Assign) else [sub.target]
                target = next((tg.value for tg in targets if isinstance(tg, ast.Subscript)), None)
            if isinstance(target, (ast.Name, ast.Attribute)):
                name = target.id if isinstance(target, ast.Name) else target.attr
                if name.isupper() and (not name.startswith("_") or name not in defined):
                    found.append(f"{where}:{sub.lineno}: {name}")
    return found


def test_no_module_registers_anything_at_import_time():
    offenders = []
    for path in sorted((REPO / "beastbt").rglob("*.py")):
        offenders += registrations(path.read_text(encoding="utf-8"), str(path.relative_to(REPO)))
    assert not offenders, "import-time registration: " + ", ".join(offenders)


def test_the_registration_check_finds_the_old_ways():
    old = ("STEPS = {}\nHOOKS = []\n\ndef register(k):\n    return lambda f: f\n\n@register('x')\ndef f():\n    pass\n\n"
           "STEPS['y'] = f\nHOOKS.append(f)\nimport beastbt.cli as cli\ncli.COMMANDS.setdefault('z', f)\n"
           "_OWN = {}\n_OWN['a'] = 1\n")
    assert [r.split(": ")[1] for r in registrations(old, "m.py")] == ["@register", "STEPS", "HOOKS", "COMMANDS"]


class _NullBase:
    """A base that takes commands and reports nothing (for assembling without devices)."""

    name = "null"

    def start(self, now_s: float) -> None:
        pass

    def send_velocity(self, cmd, now_s: float) -> None:
        pass

    def emergency_stop(self, now_s: float) -> None:
        pass

    def poll(self, now_s: float) -> list:
        return []

    def close(self) -> None:
        pass
