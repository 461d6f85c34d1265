"""``beastbt export RUN --ros2 out.mcap``: a recorded run as a ROS 2 bag (CDR in MCAP, ``ros2msg`` schemas)."""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt export``."""
    p.add_argument("run", help="a run folder (runs/<time>_<mission>/) or an .mcap recording")
    p.add_argument("--ros2", metavar="OUT.mcap", required=True,
                   help="write the run's standard channels (/odom, /tf, /scan, /fix, /imu/data, /battery, "
                        "/camera/image/compressed, /map, /plan) as a ROS 2 bag: MCAP with CDR messages, for "
                        "ros2 bag play, rviz2 and Foxglove (docs/ros2.md)")


def command(args: argparse.Namespace) -> int:
    """Export the run; print what was written. 0 done, 2 no recording or the file cannot be written."""
    from pathlib import Path

    from mcap.exceptions import McapError

    from beastbt.commands.paths import output_file_problem
    from beastbt.ros2.bag import export_ros2
    problem = output_file_problem("--ros2", args.ros2)
    if problem is not None:
        print(f"beastbt export: error: {problem}", file=sys.stderr)
        return 2
    try:
        counts = export_ros2(args.run, Path(args.ros2))
    except FileNotFoundError as exc:
        print(f"beastbt export: error: {exc}", file=sys.stderr)
        return 2
    except McapError as exc:
        print(f"beastbt export: error: {args.run}: not a beastbt recording ({exc})", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"beastbt export: error: cannot write {args.ros2}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    total = sum(counts.values())
    topics = ", ".join(f"{topic} {n}" for topic, n in sorted(counts.items())) or "none"
    print(f"wrote {args.ros2}: {total} messages ({topics}); play with 'ros2 bag play {args.ros2}'")
    return 0
