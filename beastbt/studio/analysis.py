"""What the studio shows of a text that is not saved yet: its problems, its compiled tree, what its map draws.

Each function takes the studio's folder, the text, the relative path the text
is (or will be) saved at (so ``world:`` and geo files resolve from its
folder), and a robot profile, and answers the JSON of docs/studio.md. The
checks are beastbt's own (the same as ``beastbt validate`` prints): nothing
here judges a mission by other rules.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any, Optional

from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.studio.files import FileRefused, StudioFolder, kind_of

UNSAVED_NAME = "untitled.yaml"
"""The name a text without a path is checked under (in the studio's folder)."""
DEFAULT_ROBOT = "sim"
"""The robot a mission is checked and compiled for when the page names none (``beastbt run``'s default)."""


def where(folder: StudioFolder, path: Optional[str]) -> tuple[Path, str]:
    """(the real path a text at ``path`` would have, the name its problems carry); refused outside the folder."""
    if not path:
        return folder.root / UNSAVED_NAME, UNSAVED_NAME
    return folder.resolve(path, must_exist=False), path


def robot_names(folder: StudioFolder) -> list[str]:
    """The robots the page can choose: the bundled profiles by name, then the folder's robot files by path."""
    from beastbt.core.resources import data_dir
    names = sorted(p.name[:-5] for p in data_dir("robots").iterdir() if p.name.endswith(".yaml"))
    return names + [f["path"] for f in folder.list() if f["kind"] == "robot"]


def robot_argument(folder: StudioFolder, robot: Optional[str]) -> str:
    """What ``load_profile`` takes for the page's robot: a bundled name as is, a folder file by its real path."""
    if not robot:
        return DEFAULT_ROBOT
    if robot.endswith((".yaml", ".yml")):
        return str(folder.resolve(robot))
    return robot


def problem_json(p: Problem, name: str, lines: list[str]) -> dict:
    """A problem as the API gives it: severity, line, column, end, message, hint; ``file`` when it is in another."""
    line, column = max(1, p.position.line), max(1, p.position.column)
    out: dict[str, Any] = {"severity": p.severity, "line": line, "column": column, "message": p.message}
    end = _token_end(lines, line, column)
    if end is not None:
        out["end_line"], out["end_column"] = line, end
    if p.hint:
        out["hint"] = p.hint
    if p.file != name:
        out["file"] = p.file
    return out


def _token_end(lines: list[str], line: int, column: int) -> Optional[int]:
    """The column just after the word (key, scalar or quoted text) that starts at ``line:column``."""
    if not 1 <= line <= len(lines):
        return None
    text = lines[line - 1]
    i = column - 1
    if i >= len(text):
        return None
    if text[i] in "\"'":
        close = text.find(text[i], i + 1)
        return (close + 2) if close > 0 else len(text) + 1
    j = i
    while j < len(text) and text[j] not in ",]}#" and not (text[j] == ":" and (j + 1 == len(text) or
                                                                                  text[j + 1] == " ")):
        j += 1
    while j > i and text[j - 1] == " ":
        j -= 1
    return j + 1 if j > i else None


def _sorted(problems: list[Problem]) -> list[Problem]:
    unique = {(p.file, p.position, p.message, p.severity): p for p in problems}
    return sorted(unique.values(), key=lambda p: (p.severity != "error", p.position, p.message))


def check(folder: StudioFolder, text: str, path: Optional[str], robot: Optional[str]) -> tuple[Any, list[Problem]]:
    """(the loaded mission or None, every problem of the text) as ``beastbt validate --robot ROBOT`` finds them."""
    from beastbt.validate import for_robot, internal_error, mission_with_world
    real, name = where(folder, path)
    kind = kind_of(text)
    try:
        if kind in ("world", "robot"):
            return None, _check_by_file(real, name, text, kind)
        from beastbt.mission.model import load_mission
        mission = load_mission(real, text=text, display_name=name)
        found = mission_with_world(mission)
        if not any(p.severity == "error" for p in found):
            found = found + for_robot(mission, robot_argument(folder, robot))
        return mission, found
    except InvalidInput as exc:
        return None, exc.problems
    except FileRefused:
        raise
    except Exception as exc:  # noqa: BLE001 - a slip of ours must not end in a traceback for a user's text
        return None, [internal_error(name, exc)]


def _check_by_file(real: Path, name: str, text: str, kind: str) -> list[Problem]:
    """A world or robot text, checked as the loaders check a file (written to a private temporary file)."""
    from beastbt.robot.profile import load_profile
    from beastbt.sim.world import load_world
    with tempfile.TemporaryDirectory(prefix="beastbt-studio-") as tmp:
        fake = Path(tmp) / (Path(name).name if name.endswith((".yaml", ".yml")) else "file.yaml")
        fake.write_text(text, encoding="utf-8")
        try:
            (load_world if kind == "world" else load_profile)(str(fake))
        except InvalidInput as exc:
            return [Problem(name if p.file in (str(fake), fake.name) else p.file, p.position, p.message, p.hint,
                            p.severity) for p in exc.problems]
    return []


def validate_text(folder: StudioFolder, text: str, path: Optional[str] = None, robot: Optional[str] = None) -> dict:
    """``POST /api/validate``: ``{problems: [...]}`` sorted errors first, then by position."""
    _, name = where(folder, path)
    _, problems = check(folder, text, path, robot)
    lines = text.splitlines()
    return {"problems": [problem_json(p, name, lines) for p in _sorted(problems)]}


def tree_of(folder: StudioFolder, text: str, path: Optional[str] = None, robot: Optional[str] = None) -> dict:
    """``POST /api/tree``: the compiled tree (filled in below)."""
    raise NotImplementedError


def map_of(folder: StudioFolder, text: str, path: Optional[str] = None, robot: Optional[str] = None) -> dict:
    """``POST /api/map``: what the map pane draws (filled in below)."""
    raise NotImplementedError
