"""``beastbt map ACTION``: map tools. ``map build RUN --out maps/office.yaml`` builds a map from a recorded run.

Each action is one ``(help, add_arguments, run)`` entry in :data:`ACTIONS`, so
a new one (``map show``) is a function pair and a line there. Exit status:
0 done, 1 nothing to write, 2 bad input.
"""

from __future__ import annotations

import argparse
from typing import Callable

from beastbt.commands.map_build import add_build_arguments, build

ACTIONS: dict[str, tuple[str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]] = {
    "build": ("build a map (map_server YAML + PGM) from a recorded run's LiDAR scans and odometry",
              add_build_arguments, build),
}
"""Action -> (one-line help, add its arguments, run it -> exit status)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``beastbt map ACTION ...``: one subparser per action of :data:`ACTIONS`."""
    p.description = "Map tools: " + "; ".join(f"'{name}': {help_text}" for name, (help_text, _, _) in ACTIONS.items())
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, (help_text, add, _) in ACTIONS.items():
        add(sub.add_parser(name, help=help_text))


def command(args: argparse.Namespace) -> int:
    """Run the chosen action."""
    return ACTIONS[args.action][2](args)
