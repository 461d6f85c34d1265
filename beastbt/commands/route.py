"""``beastbt route from-run RUN``: teach and repeat: write the path a recorded run drove as a GPX route."""

from __future__ import annotations

import argparse
import sys


def _distance(text: str) -> float:
    from beastbt.core.units import UnitError, parse_quantity
    try:
        value = parse_quantity(text, "distance")
    except UnitError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"'{text}' is not a positive distance")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt route``."""
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    from_run = sub.add_parser("from-run", help="write the path a recorded run drove as a GPX route")
    from_run.add_argument("run", help="a run folder (runs/<time>_<mission>/) or an .mcap recording")
    from_run.add_argument("--every", type=_distance, default=2.0, metavar="DISTANCE",
                          help="one route point every DISTANCE along the path (default 2 m)")
    from_run.add_argument("--out", metavar="FILE", default="path.gpx", help="the GPX file to write (default path.gpx)")


def command(args: argparse.Namespace) -> int:
    """Read the run's path, thin it, write the GPX; 2 when the run cannot be read or has no position."""
    from pathlib import Path

    from beastbt.commands.paths import output_file_problem, read_run
    problem = output_file_problem("--out", args.out)
    if problem is not None:
        print(f"beastbt route: error: {problem}", file=sys.stderr)
        return 2
    from beastbt.recording.teach import driven_path, thin, write_gpx
    got = read_run("route", args.run, lambda: driven_path(args.run))
    if got is None:
        return 2
    path, source = got
    points = thin(path, args.every)
    out = Path(args.out)
    write_gpx(points, out, Path(str(args.run).rstrip("/")).name)
    print(f"wrote {out}: {len(points)} points, one every {args.every:g} m of the {source} path "
          f"({len(path)} positions); repeat it with: route: {{file: {out.name}}}")
    return 0
