"""``beastbt replay RUN``: feed a recording back through the estimator and the tree; show where the commands differ."""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt replay``."""
    p.add_argument("run", help="a run folder (runs/<time>_<mission>/) or its .mcap file")
    p.add_argument("--mission", metavar="FILE", help="replay with this mission file instead of the recorded one")
    p.add_argument("--max-diffs", type=int, default=20, help="differences to print (default 20)")


def command(args: argparse.Namespace) -> int:
    """Replay a recorded run; 0 when every command matches, 1 when some differ, 2 when it cannot be read."""

    from beastbt.core.errors import InvalidInput
    from beastbt.replay import replay
    from beastbt.commands.paths import read_run
    try:
        result = read_run("replay", args.run, lambda: replay(args.run, args.mission))
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return 2
    if result is None:
        return 2
    print(f"replayed {result.ticks} ticks ({result.duration_s:.2f} s) of mission {result.mission}: "
          f"recorded {result.recorded_status or '?'}, replay {result.replay_status or 'still running at the end'}")
    for note in result.notes:
        print(f"  note: {note}")
    if result.identical:
        print("  no difference: every command matches the recording")
        return 0
    print(f"  commands differ at {result.differing_ticks} of {result.ticks} ticks; the first differences:")
    for d in result.differences[:args.max_diffs]:
        print(f"  {d.describe()}")
    return 1
