"""``beastbt validate FILE...``: check missions, robot profiles and worlds without running anything.

Exit 0 when every file is valid, else 2 with ``FILE:LINE:COLUMN: error: ...``
lines on standard error.
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of ``beastbt validate``."""
    p.add_argument("files", nargs="+", help="mission files (or robot profiles / worlds, recognised by their first key)")


def command(args: argparse.Namespace) -> int:
    """Check each file; print its problems, or 'FILE: ok'."""
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
    return 2 if bad else 0
