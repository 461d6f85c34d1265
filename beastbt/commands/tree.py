"""``beastbt tree MISSION``: print the behaviour tree a mission compiles to (and ``--dot FILE``).

The tree is compiled for the robot profile's capabilities without opening or
emulating any device, so it works for a real robot's profile on any machine.
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of ``beastbt tree``."""
    p.add_argument("mission", help="the mission file (YAML)")
    p.add_argument("--robot", default="sim", help="robot profile the tree is compiled for (default: sim)")
    p.add_argument("--dot", metavar="FILE", help="also write the tree as Graphviz DOT to FILE")


def command(args: argparse.Namespace) -> int:
    """Print the tree; 2 for an invalid mission or profile."""
    from beastbt.cli import collector_paused
    with collector_paused():  # it only loads and compiles: what it builds lives until it exits
        return _print_tree(args)


def _print_tree(args: argparse.Namespace) -> int:
    """Load, compile and print (the body of :func:`command`)."""
    import py_trees

    from beastbt.commands.paths import output_file_problem
    problem = output_file_problem("--dot", args.dot)
    if problem is not None:
        print(f"beastbt tree: error: {problem}", file=sys.stderr)
        return 2
    from beastbt.assembly import compile_for_profile
    from beastbt.core.errors import InvalidInput
    from beastbt.mission.compile import tree_to_dot
    from beastbt.mission.model import load_mission
    from beastbt.robot.profile import load_profile
    try:
        mission = load_mission(args.mission)
        profile = load_profile(args.robot)
        root = compile_for_profile(mission, profile)
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return 2
    print(py_trees.display.unicode_tree(root))
    if args.dot:
        with open(args.dot, "w", encoding="utf-8") as f:
            f.write(tree_to_dot(root))
        print(f"wrote {args.dot}")
    return 0
