"""``beastbt map build RUN --out maps/office.yaml [--resolution 5 cm]``: a map from a recorded run's LiDAR scans.

The run's ``/scan`` and ``/estimate/odom`` are fed to the same mapper as
``beastbt run --build-map`` (:mod:`beastbt.mapping.offline`). Exit status: 0
written, 1 no scan could be placed, 2 bad input (unreadable run, a run
without scans, an output that cannot be written).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, Iterator, Optional, Union

EXIT_SUCCESS, EXIT_FAILURE, EXIT_INVALID = 0, 1, 2


def _resolution(text: str) -> float:
    from beastbt.mapping.map_files import parse_resolution
    try:
        return parse_resolution(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


class NothingToMap(ValueError):
    """The recording has no LiDAR scans or no odometry to build a map from (the message says which, with a hint)."""


def mapper_from_recording(run: Union[str, Path], config: Optional[Any] = None) -> Any:
    """An :class:`~beastbt.mapping.slam.OnlineMapper` fed every ``/scan`` and ``/estimate/odom`` message of the run's
    recording (a run folder or an .mcap), with the LiDAR's mounting from its ``beastbt.run`` metadata. Raises
    :class:`NothingToMap` (a ValueError) when the run has no scans or no odometry, OSError when it cannot be read."""
    from beastbt.mapping.offline import NO_SCANS_HINT, build_offline
    from beastbt.recording.foxglove import scan_of
    from beastbt.recording.reader import find_recording, read_recording

    path = find_recording(run)
    rec = read_recording(path, topics=("/scan", "/estimate/odom"), keep_order=True)
    if not rec.messages.get("/scan"):
        raise NothingToMap(f"{path}: the recording has no LiDAR scans (/scan) to build a map from; {NO_SCANS_HINT}")
    if not rec.messages.get("/estimate/odom"):
        raise NothingToMap(f"{path}: the recording has no odometry (/estimate/odom) to place its scans; "
                           f"{NO_SCANS_HINT}")
    mounting = json.loads(rec.info.get("lidar_mounting") or "{}")

    def messages() -> Iterator[tuple[str, Any]]:
        for topic, _, m in rec.order:
            if topic == "/estimate/odom":
                yield "odom", (float(m["stamp_s"]), float(m["x"]), float(m["y"]), float(m["yaw"]),
                               float(m.get("yaw_rate_rps") or 0.0))
            elif topic == "/scan":
                yield "scan", scan_of(m)

    return build_offline(messages(), (float(mounting.get("x_m", 0.0)), float(mounting.get("y_m", 0.0))),
                         math.radians(float(mounting.get("yaw_deg", 0.0))), config)


def add_build_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt map build``."""
    p.add_argument("run", help="a run folder (runs/<time>_<mission>/) or an .mcap recording with LiDAR scans")
    p.add_argument("--out", metavar="FILE", required=True,
                   help="the map to write: a map_server YAML with a PGM beside it, e.g. maps/office.yaml")
    p.add_argument("--resolution", metavar="SIZE", type=_resolution, default=None,
                   help="cell size, e.g. '5 cm' (default)")


def build(args: argparse.Namespace) -> int:
    """Build the map from the run's scans and odometry and write it; 2 when the run cannot be read or has none."""
    from beastbt.commands.paths import read_run
    from beastbt.mapping.map_files import map_output_problem
    from beastbt.mapping.occupancy_map import save_map
    from beastbt.mapping.slam import MappingConfig

    problem = map_output_problem("--out", args.out)
    if problem is not None:
        print(f"beastbt map build: error: {problem}", file=sys.stderr)
        return EXIT_INVALID
    config = MappingConfig(resolution_m=args.resolution or MappingConfig.resolution_m)
    mapper = read_run("map build", args.run, lambda: mapper_from_recording(args.run, config))
    if mapper is None:
        return EXIT_INVALID
    if not mapper.keyframes:
        print(f"beastbt map build: error: {args.run}: no scan could be placed ({mapper.stats.scans} scans, none "
              f"while the odometry was known)", file=sys.stderr)
        return EXIT_FAILURE
    mapper.optimise()
    grid = mapper.occupancy_map()
    assert grid is not None
    yaml_path, image_path = save_map(grid, args.out)
    s = mapper.stats
    print(f"map written to {yaml_path} (image {image_path}; {grid.cols} x {grid.rows} cells at "
          f"{grid.resolution_m * 100:g} cm; {s.scans} scans, {s.keyframes} keyframes, {s.loops_closed} loop closures)")
    return EXIT_SUCCESS


__all__ = ["add_build_arguments", "build", "mapper_from_recording", "NothingToMap"]
