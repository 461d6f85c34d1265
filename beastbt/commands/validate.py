"""``beastbt validate FILE...``: check missions, robot profiles and worlds without running anything.

Exit 0 when every file is valid, else 2 with ``FILE:LINE:COLUMN: error: ...``
lines on standard error. Warnings (``FILE:LINE:COLUMN: warning: ...``) do not
change the exit status unless ``--strict`` is given. A speed above the robot's
top speed is a warning, as it is when the mission runs: the robot of
``--robot PROFILE``, or ``sim``, the one ``beastbt run`` uses without it.
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of ``beastbt validate``."""
    p.add_argument("files", nargs="*", help="mission files (or robot profiles / worlds, recognised by their first key; "
                                            "joystick scripts, a list)")
    p.add_argument("--strict", action="store_true", help="count warnings as errors (exit 2)")
    p.add_argument("--robot", metavar="PROFILE",
                   help="also check missions for this robot, as 'beastbt run --robot' would (its top speed; a "
                        "battery, joystick, LiDAR or odometry the mission needs and the robot lacks); without it, "
                        "speeds are checked against the top speed of 'sim', the robot 'beastbt run' uses")
    p.add_argument("--explain", metavar="STEP", help="print a short help for a step (from the mission schema) and exit")


def command(args: argparse.Namespace) -> int:
    """Check each file; print its problems, or 'FILE: ok'. 2 when any has an error (or, with --strict, a warning)."""
    if args.explain:
        from beastbt.mission.explain import explain_step, unknown_step_message
        text = explain_step(args.explain)
        if text is None:
            print(f"beastbt validate: error: {unknown_step_message(args.explain)}", file=sys.stderr)
            return 2
        print(text)
        return 0
    if not args.files:
        print("beastbt validate: error: give the files to check (or --explain STEP)", file=sys.stderr)
        return 2
    from beastbt.cli import collector_paused
    with collector_paused():  # it only reads and checks: the schemas and code it loads live until it exits
        return _validate_files(args)


def _validate_files(args: argparse.Namespace) -> int:
    """Check each of ``args.files`` and print what was found (the body of :func:`command`)."""
    from beastbt.validate import validate_file
    bad = 0
    for f in args.files:
        problems = validate_file(f, args.robot)
        errors = [p for p in problems if p.severity == "error" or args.strict]
        for p in problems:
            print(p.format(), file=sys.stderr)
        if errors:
            bad += 1
        elif problems:
            n = len(problems)
            print(f"{f}: ok, with {n} warning{'' if n == 1 else 's'} (--strict refuses {'it' if n == 1 else 'them'})")
        else:
            print(f"{f}: ok")
    return 2 if bad else 0
