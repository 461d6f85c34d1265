"""``--fleet ENDPOINT`` and ``--fleet-config FILE`` to a Zenoh configuration, for a robot and for the station.

A robot is a Zenoh *peer* that connects to the station's router: it opens at
once whether or not the station is up, keeps trying in the background
(``exit_on_failure: false``) and comes back by itself when the station does,
so a run never waits for, or stops because of, the fleet link. The station is
a *router* that listens. Neither scouts by multicast nor gossips: a robot
talks to the endpoint it was given, nothing else on the network is probed,
and nothing listens on a robot.

``--fleet-config FILE`` is a standard Zenoh JSON5 configuration (TLS,
user/password, access control: see ``beastbt station --init-keys``); it is
taken as written, and ``--fleet`` / ``--listen``, when given too, set its
endpoints.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

from beastbt.core.errors import InvalidInput, Position, Problem

DEFAULT_PORT = 7447
"""Zenoh's own default port."""
_ENDPOINT = re.compile(r"(?P<proto>[a-z0-9]+)/(?P<addr>\[[0-9a-fA-F:.]+\]|[^/:\[\]#?]+):(?P<port>\d{1,5})"
                       r"(?P<tail>[?#].*)?")
PROTOCOLS = ("tcp", "tls", "quic", "udp")
"""The transports an endpoint may name."""
RETRY = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}
"""How often a robot tries the station again while it is away (ms): back within a second of its return."""
OPEN_TIMEOUT_MS = 500
"""How long opening a robot's session waits for the station before it goes on without it (ms)."""


@dataclass(frozen=True)
class FleetOptions:
    """How a run or an agent reaches the fleet: ``endpoint`` (``tcp/HOST:PORT``), a Zenoh JSON5 ``config_file``,
    the robot's ``name`` (None: the profile's), and, for ``beastbt serve``, the long-lived ``agent`` the run
    reports through (None: the run opens its own)."""

    endpoint: Optional[str] = None
    config_file: Optional[str] = None
    name: Optional[str] = None
    agent: Any = None


def parse_endpoint(text: str, option: str = "--fleet") -> str:
    """``tcp/HOST:PORT`` (also ``HOST:PORT`` and ``PORT``, taken as TCP) -> a Zenoh endpoint; ValueError otherwise."""
    text = str(text).strip()
    if re.fullmatch(r"\d{1,5}", text):
        text = f"tcp/127.0.0.1:{text}"
    elif "/" not in text:
        text = f"tcp/{text}"
    m = _ENDPOINT.fullmatch(text)
    if m is None or m["proto"] not in PROTOCOLS:
        raise ValueError(f"{option} takes a Zenoh endpoint such as tcp/127.0.0.1:{DEFAULT_PORT} (or "
                         f"tls/HOST:PORT with --fleet-config), not '{text[:80]}'")
    if not 0 < int(m["port"]) <= 65535:
        raise ValueError(f"{option} port must be 1..65535, not {m['port']}")
    return text


def _load(config_file: str, option: str) -> Any:
    import zenoh
    path = Path(config_file)
    if not path.is_file():
        raise InvalidInput([Problem(option, Position(), f"no Zenoh configuration file '{config_file}'",
                                    "give a JSON5 file such as the ones 'beastbt station --init-keys DIR' writes")])
    try:
        return zenoh.Config.from_file(str(path))
    except Exception as exc:  # noqa: BLE001 - zenoh says what is wrong in its own words
        text = str(exc).split(" at /")[0]  # not where in zenoh's own source it was found
        where = re.search(r"line: (\d+), column: (\d+)", text) or re.search(r"--> (\d+):(\d+)", text)
        position = Position(int(where[1]), int(where[2])) if where else Position(1, 1)
        message = re.sub(r"\s+", " ", text.split("location:")[0]).strip(" ,")
        raise InvalidInput([Problem(str(path), position, f"not a Zenoh configuration: {message[:300]}",
                                    "a standard Zenoh JSON5 configuration (zenoh.io: Configuration)")]) from None


def _insert(config: Any, key: str, value: Any) -> None:
    config.insert_json5(key, json.dumps(value))


def robot_config(options: FleetOptions) -> Any:
    """The Zenoh configuration of a robot (a peer connecting to the station; see the module docstring)."""
    import zenoh
    if options.config_file:
        config = _load(options.config_file, "--fleet-config")
    else:
        config = zenoh.Config()
        _insert(config, "mode", "peer")
        _insert(config, "listen/endpoints", [])  # nothing listens on a robot
        _insert(config, "scouting/multicast/enabled", False)
        _insert(config, "scouting/gossip/enabled", False)
        _insert(config, "connect/timeout_ms", OPEN_TIMEOUT_MS)
        _insert(config, "connect/exit_on_failure", False)
        _insert(config, "connect/retry", RETRY)
    if options.endpoint:
        _insert(config, "connect/endpoints", [options.endpoint])
    return config


def station_config(listen: Optional[str], config_file: Optional[str] = None) -> Any:
    """The Zenoh configuration of the station: a router listening on ``listen``."""
    import zenoh
    if config_file:
        config = _load(config_file, "--fleet-config")
    else:
        config = zenoh.Config()
        _insert(config, "mode", "router")
        _insert(config, "scouting/multicast/enabled", False)
        _insert(config, "scouting/gossip/enabled", False)
        _insert(config, "connect/endpoints", [])
    if listen:
        _insert(config, "listen/endpoints", [listen])
    return config


__all__ = ["FleetOptions", "parse_endpoint", "robot_config", "station_config", "DEFAULT_PORT"]
