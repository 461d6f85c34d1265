"""``beastbt runs [keep|unkeep|prune]``: the recorded runs, one line each, oldest first; keep one from pruning,
or prune now.

``beastbt runs`` lists them. ``beastbt runs keep RUN`` marks a run so that pruning never deletes it
(``unkeep`` takes the mark away); ``beastbt runs prune`` deletes the oldest finished runs until the rules hold
(``--keep N``, ``--max-total-mb MB``, ``--min-free-mb MB``; ``--dry-run`` says what it would delete). Runs also
prune themselves when they start, by the profile's ``runs:`` (docs/recording.md). Exit status: 0 done, 2 a run
that is not there.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt runs``."""
    p.add_argument("action", nargs="?", choices=("list", "keep", "unkeep", "prune"), default="list",
                   help="list (default), keep RUN, unkeep RUN, or prune")
    p.add_argument("run", nargs="?", metavar="RUN", help="with keep/unkeep: the run folder (path, or name in "
                                                          "--runs-dir)")
    p.add_argument("--runs-dir", default="runs", help="where the run folders are (default: ./runs)")
    p.add_argument("--why", default="", help="with keep: a note kept in the run's KEEP file")
    p.add_argument("--keep", type=int, metavar="N", help="with prune: keep the newest N finished runs")
    p.add_argument("--max-total-mb", type=float, metavar="MB", help="with prune: at most this much in all")
    p.add_argument("--min-free-mb", type=float, metavar="MB", default=None,
                   help="with prune: keep this much free on the disk (default 0 here: only the rules given)")
    p.add_argument("--dry-run", action="store_true", help="with prune: say what would go, delete nothing")


def command(args: argparse.Namespace) -> int:
    """List, mark or prune the recorded runs."""
    if args.action in ("keep", "unkeep"):
        return _keep(args)
    if args.action == "prune":
        return _prune(args)
    from beastbt.recording.runs_list import list_runs, table
    runs = list_runs(args.runs_dir)
    if not runs:
        print(f"no runs in {args.runs_dir}")
        return 0
    for line in table(runs):
        print(line)
    return 0


def _run_folder(args: argparse.Namespace) -> Path | None:
    if not args.run:
        print(f"beastbt runs {args.action}: error: name the run (a folder in {args.runs_dir}, or its path)",
              file=sys.stderr)
        return None
    for candidate in (Path(args.run), Path(args.runs_dir) / args.run):
        if candidate.is_dir() and ((candidate / "summary.json").exists() or (candidate / "run.mcap").exists()):
            return candidate
    print(f"beastbt runs {args.action}: error: {args.run}: no such run (beastbt runs --runs-dir {args.runs_dir} "
          f"lists them)", file=sys.stderr)
    return None


def _keep(args: argparse.Namespace) -> int:
    from beastbt.run.retention import mark_kept
    folder = _run_folder(args)
    if folder is None:
        return 2
    mark_kept(folder, args.action == "keep", args.why)
    print(f"{folder}: {'kept: never pruned' if args.action == 'keep' else 'no longer kept: pruned like any other'}")
    return 0


def _prune(args: argparse.Namespace) -> int:
    from beastbt.run.retention import RunsPolicy, prune_runs
    policy = RunsPolicy(keep=args.keep, max_total_mb=args.max_total_mb, min_free_mb=args.min_free_mb or 0.0)
    pruned = prune_runs(Path(args.runs_dir), policy, dry_run=args.dry_run, log=print)
    if not pruned:
        print(f"nothing to prune in {args.runs_dir}")
    return 0
