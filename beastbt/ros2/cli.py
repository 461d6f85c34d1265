"""``--ros2 [ENDPOINT]`` and ``--ros2-config FILE`` of ``beastbt run`` and ``beastbt serve`` (docs/ros2.md)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Optional

ROS2_DEFAULT = "profile"
"""``--ros2`` with no endpoint: the profile's ``ros2: listen:``, else tcp/127.0.0.1:7447."""


def _endpoint(text: str) -> str:
    if text == ROS2_DEFAULT:
        return text  # a bare --ros2 (argparse passes the const through the type too)
    from beastbt.fleet.config import parse_endpoint
    try:
        return parse_endpoint(text, "--ros2")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).replace("--fleet-config", "--ros2-config")) from None


def add_ros2_arguments(p: argparse.ArgumentParser) -> None:
    """Add ``--ros2 [ENDPOINT]`` and ``--ros2-config FILE``."""
    p.add_argument("--ros2", metavar="ENDPOINT", nargs="?", const=ROS2_DEFAULT, type=_endpoint,
                   help="show the run to ROS 2 over Zenoh: topics out (/odom, /tf, /scan, /map...), /cmd_vel, "
                        "/goal_pose, /initialpose and /estop in; a laptop on rmw_zenoh_cpp or zenoh-bridge-ros2dds "
                        "connects to ENDPOINT (default: the profile's ros2: listen, else tcp/127.0.0.1:7447); "
                        "plain TCP beyond loopback publishes only (docs/ros2.md)")
    p.add_argument("--ros2-config", metavar="FILE",
                   help="a standard Zenoh JSON5 configuration for the ROS 2 link (TLS, access control): commands "
                        "are then taken from whom it admits")


def ros2_options(args: argparse.Namespace, command: str) -> tuple[Optional[dict[str, Any]], Optional[str]]:
    """The run's ``ros2`` option (None without ``--ros2``), or an error message."""
    ros2 = getattr(args, "ros2", None)
    config = getattr(args, "ros2_config", None)
    if ros2 is None and config is None:
        return None, None
    if config is not None and not Path(config).is_file():
        return None, f"beastbt {command}: error: --ros2-config {config}: no such file (a Zenoh JSON5 configuration)"
    return {"listen": None if ros2 in (None, ROS2_DEFAULT) else ros2, "config": config}, None


__all__ = ["add_ros2_arguments", "ros2_options"]
