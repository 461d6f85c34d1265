"""The layers of beastbt follow the flow of a tick: no import cycle, and no lower layer importing a higher one.

Every ``import`` and ``from ... import`` of every module under ``beastbt/`` is
read with :mod:`ast`, at any depth (a function-level import counts: it runs
too), except under ``if TYPE_CHECKING:`` (annotations only, never run).
``docs/architecture.md`` shows the same table.
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Iterable, Optional

from conftest import REPO

LAYERS: tuple[tuple[int, tuple[str, ...], str], ...] = (
    (0, ("core",), "clock, events, errors with positions, units, YAML with positions, schema loading, config helpers"),
    (1, ("blackboard",), "the reading and command types, the catalogue of blackboard keys"),
    (2, ("devices",), "drivers that speak each device's wire protocol, and the port interfaces they use"),
    (3, ("estimation", "vision", "actuation", "navigation", "mapping"), "EKF and geodesy; line detection; mux, gate, "
                                                                          "watchdog, base adapters; local costmap and "
                                                                          "planner; occupancy maps and SLAM"),
    (4, ("sim",), "the world, the dynamics, and an emulator behind every device's port"),
    (5, ("behaviours",), "leaf behaviours and flow decorators, one small class each"),
    (6, ("mission",), "the mission model and the compiler to a tree"),
    (7, ("robot",), "the robot profile, its ports (RobotIO) and the part protocol"),
    (8, ("run",), "the tick loop, safety wiring, failsafes, the session, the summary, run folders"),
    (9, ("recording",), "the recorder and its writer process, the reader, the report, the list of runs"),
    (10, ("parts", "live", "fleet", "ros2"), "each part of a robot (a device on the robot and the simulator, a "
                                             "feature); live video; the fleet (Zenoh); ROS 2 over Zenoh"),
    (11, ("commands", "studio", "testing", "<top>"), "the subcommands and the top-level modules: assembly (the "
                                                     "composition root), replay, validate, cli; the studio (it checks "
                                                     "with validate); testing (the harness, mission tests)"),
)
"""(rank, packages, what they hold): a module may import its own rank (without cycles) and lower ranks only."""

RANK = {package: rank for rank, packages, _ in LAYERS for package in packages}


def module_name(path: Path, root: Path) -> str:
    """``beastbt/run/runner.py`` -> ``beastbt.run.runner`` (``__init__`` is its package)."""
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def layer_of(module: str, packages: set[str]) -> str:
    """The package of a beastbt module (``run``), or ``<top>`` for ``beastbt.cli`` and the like."""
    parts = module.split(".")
    if len(parts) >= 2 and parts[1] in packages:
        return parts[1]
    return "<top>"


def _type_checking_only(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def imports_of(source: str, module: str, is_package: bool) -> list[tuple[str, int]]:
    """``(imported beastbt module, line)`` for every import that runs (not those under ``if TYPE_CHECKING``)."""
    found: list[tuple[str, int]] = []

    def visit(nodes: Iterable[ast.AST]) -> None:
        for node in nodes:
            if isinstance(node, ast.If) and _type_checking_only(node):
                visit(node.orelse)
                continue
            if isinstance(node, ast.Import):
                found.extend((a.name, node.lineno) for a in node.names if a.name.startswith("beastbt."))
            elif isinstance(node, ast.ImportFrom):
                target: Optional[str] = node.module
                if node.level:
                    base = module.split(".") if is_package else module.split(".")[:-1]
                    base = base[:len(base) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                if target and target.startswith("beastbt"):
                    if target != "beastbt":
                        found.append((target, node.lineno))
                    # ``from beastbt.core import clock`` imports the module beastbt.core.clock too (the graph
                    # keeps only the names that are modules).
                    found.extend((f"{target}.{a.name}", node.lineno) for a in node.names)
            visit(ast.iter_child_nodes(node))

    visit(ast.parse(source).body)
    return found


def import_graph(root: Path) -> dict[str, list[tuple[str, int]]]:
    """Every beastbt module under ``root`` -> the beastbt modules it imports (with the line)."""
    graph = {}
    for path in sorted(root.rglob("*.py")):
        name = module_name(path, root)
        graph[name] = imports_of(path.read_text(encoding="utf-8"), name, path.name == "__init__.py")
    packages = {m for m in graph} | {m.rsplit(".", 1)[0] for m in graph}
    return {m: [(t, line) for t, line in imps if t in graph or t.rsplit(".", 1)[0] not in packages]
            for m, imps in graph.items()}


def violations(graph: dict[str, list[tuple[str, int]]], packages: set[str]) -> list[str]:
    """Imports from a lower layer into a higher one, each as ``module:line imports target (layer a < layer b)``."""
    out = []
    for module, imports in graph.items():
        here = layer_of(module, packages)
        for target, line in imports:
            there = layer_of(target, packages)
            if target != "beastbt" and RANK[there] > RANK[here]:
                out.append(f"{module}:{line} imports {target}: layer '{here}' ({RANK[here]}) may not import "
                           f"'{there}' ({RANK[there]})")
    return out


def cycles(graph: dict[str, list[tuple[str, int]]]) -> list[list[str]]:
    """Import cycles among the modules of ``graph`` (each as the list of modules around it)."""
    edges = {m: sorted({t for t, _ in imps if t in graph and t != m}) for m, imps in graph.items()}
    found: list[list[str]] = []
    state: dict[str, int] = {}
    stack: list[str] = []

    def walk(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in edges[m]:
            if state.get(t) == 1:
                found.append(stack[stack.index(t):] + [t])
            elif t not in state:
                walk(t)
        stack.pop()
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            walk(m)
    return found


PACKAGES = {p.name for p in (REPO / "beastbt").iterdir() if p.is_dir() and (p / "__init__.py").exists()}


def test_every_package_has_a_layer():
    assert PACKAGES <= set(RANK), f"add these packages to LAYERS: {sorted(PACKAGES - set(RANK))}"


def test_no_lower_layer_imports_a_higher_one():
    bad = violations(import_graph(REPO / "beastbt"), PACKAGES)
    assert not bad, "\n".join(bad)


def test_no_import_cycle_among_beastbt_modules():
    found = cycles(import_graph(REPO / "beastbt"))
    assert not found, "\n".join(" -> ".join(c) for c in found)


def test_core_imports_nothing_of_beastbt_and_devices_only_core_and_blackboard():
    graph = import_graph(REPO / "beastbt")
    for module, imports in graph.items():
        layer = layer_of(module, PACKAGES)
        allowed = {"core"} if layer == "core" else {"core", "blackboard", "devices"} if layer == "devices" else None
        if allowed is not None:
            assert {layer_of(t, PACKAGES) for t, _ in imports} <= allowed, module


def test_the_checks_find_a_violation_and_a_cycle(tmp_path):
    src = tmp_path / "beastbt"
    (src / "core").mkdir(parents=True)
    (src / "run").mkdir()
    for pkg in (src, src / "core", src / "run"):
        (pkg / "__init__.py").write_text("")
    (src / "core" / "clock.py").write_text("import beastbt.run.loop\n")
    (src / "run" / "loop.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import beastbt.cli\nfrom beastbt.core import clock\n")
    (src / "cli.py").write_text("def main():\n    from . import run\n")
    graph = import_graph(src)
    assert violations(graph, {"core", "run"}) == [
        "beastbt.core.clock:1 imports beastbt.run.loop: layer 'core' (0) may not import 'run' (8)"]
    assert cycles(graph) == [["beastbt.core.clock", "beastbt.run.loop", "beastbt.core.clock"]]
    assert ("beastbt.run", 2) in graph["beastbt.cli"]  # a function-level, relative import counts
