"""``beastbt report RUN``: summarise a recorded run and draw its plots (``report/`` with ``report.html``)."""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt report``."""
    p.add_argument("run", help="a run folder (runs/<time>_<mission>/) or an .mcap recording")
    p.add_argument("--out", metavar="DIR", help="where the plots and report.html go (default: report/ in the run folder)")


def command(args: argparse.Namespace) -> int:
    """Summarise a recorded run and plot it (PNG plots and report.html); 2 when it cannot be read."""
    from beastbt.recording.report import make_report
    try:
        report = make_report(args.run, args.out)
    except (OSError, ValueError) as exc:
        print(f"beastbt report: error: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # mcap's InvalidMagic and friends: not a recording
        print(f"beastbt report: error: {args.run}: cannot read the recording ({exc})", file=sys.stderr)
        return 2
    print(report.text)
    print(f"  report: {report.html} ({len(report.plots)} plots"
          + (f"; not plotted: {', '.join(f'{k} ({v})' for k, v in report.skipped.items())}" if report.skipped else "")
          + ")")
    return 0
