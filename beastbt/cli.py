"""The ``beastbt`` command: run, validate and inspect missions.

Exit status: 0 the mission succeeded (or every file is valid), 1 it failed or
was stopped, 2 invalid input (nothing moved).
"""

from __future__ import annotations

import argparse
import sys
from typing import Callable, Optional, Sequence

from beastbt.core.errors import InvalidInput
from beastbt.core.units import UnitError, parse_duration

EXIT_SUCCESS = 0
EXIT_FAILURE = 1
EXIT_INVALID = 2

COMMANDS: dict[str, tuple[Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]] = {}
"""Subcommands that parts of beastbt add: name -> (add_arguments, handler)."""
RUN_OPTIONS: list[Callable[[argparse.ArgumentParser], None]] = []
"""Extra options of ``beastbt run`` that parts of beastbt add (``--joystick``, ``--stream``...)."""


def _load_plugins() -> None:
    """Import the parts of beastbt that extend the CLI, the compiler and the simulator."""
    import beastbt.plugins  # noqa: F401  (registers everything optional that is installed)


def _duration(text: str) -> float:
    try:
        return parse_duration(text)
    except UnitError as exc:
        raise argparse.ArgumentTypeError(str(exc))


def _add_run(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", help="the mission file (YAML)")
    p.add_argument("--robot", default="sim", help="'sim' (default: the built-in simulator) or a robot profile file")
    p.add_argument("--world", help="simulated world file (default: the mission's 'world:')")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulator (default 0)")
    p.add_argument("--speed", default="max", help="max (default), realtime, or a factor of real time such as 10")
    p.add_argument("--max-time", type=_duration, help="end the run after this much mission time, e.g. '10 min'")
    p.add_argument("--summary", metavar="FILE", help="write the run summary as JSON to FILE")
    p.add_argument("--record", metavar="FILE", help="also write the run's recording to FILE")
    p.add_argument("--runs-dir", default="runs", help="where run folders go (default: ./runs)")
    p.add_argument("--no-record", action="store_true", help="do not write a run folder")
    p.add_argument("--sim", action="store_true", help="run a real robot profile on the simulator (same geometry and limits)")
    for add in RUN_OPTIONS:
        add(p)


def _cmd_run(args: argparse.Namespace) -> int:
    from beastbt.robot.hardware import DeviceUnavailable
    from beastbt.run.session import RunOptions, execute, parse_speed, prepare
    from beastbt.run.summary import human_summary
    try:
        speed = parse_speed(args.speed)
    except ValueError as exc:
        print(f"beastbt run: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    extras = {k: v for k, v in vars(args).items() if k not in {
        "mission", "robot", "world", "seed", "speed", "max_time", "summary", "record", "runs_dir", "no_record", "func", "command"}}
    extras["simulate"] = args.sim
    opts = RunOptions(robot=args.robot, world=args.world, seed=args.seed, speed=speed, max_time_s=args.max_time,
                      summary_path=args.summary, record_path=args.record, runs_dir=args.runs_dir,
                      record=not args.no_record, status_line=sys.stdout.isatty(), extras=extras)
    try:
        prepared = prepare(args.mission, opts)
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return EXIT_INVALID
    except DeviceUnavailable as exc:
        print(f"beastbt run: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    summary = execute(prepared, sys.stdout)
    print(human_summary(summary))
    return EXIT_SUCCESS if summary["status"] == "success" else EXIT_FAILURE


def _add_validate(p: argparse.ArgumentParser) -> None:
    p.add_argument("files", nargs="+", help="mission files (or robot profiles / worlds, recognised by their first key)")


def _cmd_validate(args: argparse.Namespace) -> int:
    from beastbt.validate import validate_file
    bad = 0
    for f in args.files:
        problems = validate_file(f)
        if problems:
            bad += 1
            for p in problems:
                print(p.format(), file=sys.stderr)
        else:
            print(f"{f}: ok")
    return EXIT_INVALID if bad else EXIT_SUCCESS


def _add_tree(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", help="the mission file (YAML)")
    p.add_argument("--robot", default="sim", help="robot profile the tree is compiled for (default: sim)")
    p.add_argument("--dot", metavar="FILE", help="also write the tree as Graphviz DOT to FILE")


def _cmd_tree(args: argparse.Namespace) -> int:
    import py_trees
    from beastbt.mission.compile import tree_to_dot
    from beastbt.run.session import RunOptions, prepare
    try:
        prepared = prepare(args.mission, RunOptions(robot=args.robot, record=False))
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return EXIT_INVALID
    root = prepared.run.root
    print(py_trees.display.unicode_tree(root))
    if args.dot:
        with open(args.dot, "w", encoding="utf-8") as f:
            f.write(tree_to_dot(root))
        print(f"wrote {args.dot}")
    prepared.run.io.close()
    return EXIT_SUCCESS


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``beastbt`` command."""
    parser = argparse.ArgumentParser(prog="beastbt", description="Run YAML missions as behaviour trees on a robot or its simulator.")
    sub = parser.add_subparsers(dest="command", required=True)
    builtin = {
        "run": (_add_run, _cmd_run, "run a mission (on the simulator unless --robot names a profile)"),
        "validate": (_add_validate, _cmd_validate, "check mission files; errors as FILE:LINE:COLUMN"),
        "tree": (_add_tree, _cmd_tree, "print the behaviour tree a mission compiles to"),
    }
    for name, (add, handler, help_text) in builtin.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        add(p)
        p.set_defaults(func=handler)
    for name, (add, handler) in COMMANDS.items():
        p = sub.add_parser(name, help=(handler.__doc__ or "").strip().splitlines()[0] if handler.__doc__ else None)
        add(p)
        p.set_defaults(func=handler)
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of the ``beastbt`` console script; returns the exit status."""
    _load_plugins()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
