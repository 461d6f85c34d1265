"""``beastbt report RUN``: summarise a recorded run and draw its plots (``report/`` with ``report.html``)."""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt report``."""
    p.add_argument("run", help="a run folder (runs/<time>_<mission>/) or an .mcap recording")
    p.add_argument("--out", metavar="DIR", help="where the plots and report.html go (default: report/ in the run folder)")


def command(args: argparse.Namespace) -> int:
    """Summarise a recorded run and plot it (PNG plots and report.html); 2 when it cannot be read."""
    from beastbt.commands.paths import read_run
    from beastbt.recording.report import make_report
    report = read_run("report", args.run, lambda: make_report(args.run, args.out))
    if report is None:
        return 2
    print(report.text)
    print(f"  report: {report.html} ({len(report.plots)} plots"
          + (f"; not plotted: {', '.join(f'{k} ({v})' for k, v in report.skipped.items())}" if report.skipped else "")
          + ")")
    return 0
