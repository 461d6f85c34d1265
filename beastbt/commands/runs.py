"""``beastbt runs``: the recorded runs, one line each, oldest first."""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt runs``."""
    p.add_argument("--runs-dir", default="runs", help="where the run folders are (default: ./runs)")


def command(args: argparse.Namespace) -> int:
    """List the recorded runs with their outcome, one line each."""
    from beastbt.recording.runs_list import list_runs, table
    runs = list_runs(args.runs_dir)
    if not runs:
        print(f"no runs in {args.runs_dir}")
        return 0
    for line in table(runs):
        print(line)
    return 0
