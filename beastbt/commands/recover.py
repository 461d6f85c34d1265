"""``beastbt recover RUN``: rewrite a recording cut short (power cut, full disk) as a whole MCAP file."""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt recover``."""
    p.add_argument("run", help="a run folder (runs/<time>_<mission>/) or an .mcap recording")


def command(args: argparse.Namespace) -> int:
    """Recover the run's recording in place (the cut file kept as ``.cut``) and a missing summary; 2 when it
    cannot be done."""
    from beastbt.recording.recover import RecoveryError, recover
    try:
        r = recover(args.run)
    except RecoveryError as exc:
        print(f"beastbt recover: error: {exc}", file=sys.stderr)
        return 2
    if r.complete:
        print(f"{r.recording} is complete: nothing to recover")
    else:
        print(f"recovered {r.recording}: {r.messages} messages kept ({r.bytes_kept} of {r.bytes_total} bytes; "
              f"reading stopped: {r.reason}); the cut file is kept as {r.backup}")
    if r.summary is not None:
        print(f"rebuilt {r.summary} from the recording")
    for note in r.notes:
        print(f"beastbt recover: {note}", file=sys.stderr)
    return 2 if r.notes else 0
