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
taken as written, except that a relative certificate or key file in its
``transport/link/tls`` section is found beside the file (so that a robot's
enrolment folder can be copied anywhere), and ``--fleet`` / ``--listen``,
when given too, set its endpoints.

**Safe by default** (:func:`robot_link`): a robot joins with keys, the
``--fleet-config`` it is given or the ``robot.json5`` of the per-user fleet
folder (:func:`fleet_folder`, where ``beastbt station`` makes its keys and a
robot's enrolment is copied to). Plain TCP needs ``--insecure-loopback``; and
plain TCP, asked for or not, never goes beyond loopback, on either side
(:func:`plain_problem`): any program of any user of a computer can reach its
loopback, but nothing else can.
"""

from __future__ import annotations

import json
import os
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
PLAIN = ("tcp", "udp")
"""The transports that carry no TLS: loopback only, and only when asked for (``--insecure-loopback``)."""
ROBOT_CONFIG = "robot.json5"
"""The robot's Zenoh configuration in the fleet folder (its enrolment, or on the station the robots' own)."""
INSECURE_ROBOT_WARNING = """beastbt {command}: WARNING: --insecure-loopback: the fleet link is plain TCP, with no keys.
    Any program of any user of this computer can command this robot (send it missions, pause, abort,
    reset its e-stop) and pose as its station. For a bench only (docs/fleet.md)."""
"""What a robot says when it joins without keys."""
TLS_FILES = ("root_ca_certificate", "listen_private_key", "listen_certificate", "connect_private_key",
             "connect_certificate")
"""The files a configuration's ``transport/link/tls`` names: relative ones are found beside the configuration."""


@dataclass(frozen=True)
class FleetOptions:
    """How a run or an agent reaches the fleet: ``endpoint`` (``tcp/HOST:PORT``), a Zenoh JSON5 ``config_file``,
    the robot's ``name`` (None: the profile's), and, for ``beastbt serve``, the long-lived ``agent`` the run
    reports through (None: the run opens its own)."""

    endpoint: Optional[str] = None
    config_file: Optional[str] = None
    name: Optional[str] = None
    agent: Any = None


def fleet_folder() -> Path:
    """The per-user fleet folder (``$XDG_STATE_HOME/beastbt/fleet``, by default ``~/.local/state/beastbt/fleet``):
    on the station its keys, made on its first start; on a robot its enrolment (``robot.json5`` and the files it
    names), copied from the station."""
    state = os.environ.get("XDG_STATE_HOME") or ""
    base = Path(state) if Path(state).is_absolute() else Path.home() / ".local" / "state"
    return base / "beastbt" / "fleet"


def endpoint_host(endpoint: str) -> str:
    """The host of a Zenoh endpoint (``tcp/127.0.0.1:7447`` -> ``127.0.0.1``, ``tls/[::1]:7447`` -> ``::1``)."""
    m = _ENDPOINT.fullmatch(endpoint)
    return m["addr"].strip("[]") if m else ""


def is_plain(endpoint: str) -> bool:
    """Whether ``endpoint`` carries no TLS (``tcp/``, ``udp/``)."""
    return endpoint.split("/", 1)[0] in PLAIN


def plain_problem(endpoint: Optional[str], option: str) -> Optional[str]:
    """Why plain ``endpoint`` may not be used without keys (it is not on loopback), or None when it may."""
    from beastbt.live.endpoint import is_loopback
    if endpoint is None or not is_plain(endpoint) or is_loopback(endpoint_host(endpoint)):
        return None
    return (f"{option} {endpoint}: plain TCP without keys is for this computer only (127.0.0.1): anyone on the "
            f"network could read and command the robots; use tls/ with the fleet's keys (docs/fleet.md)")


def robot_link(endpoint: Optional[str], config_file: Optional[str], insecure_loopback: bool = False,
               command: str = "serve") -> tuple[Optional[str], Optional[str]]:
    """A robot's ``(endpoint, config_file)`` as it joins the fleet, safe by default (module docstring); ValueError
    saying what to do when it may not join that way.

    With ``config_file``, as given. Without it: with ``insecure_loopback``, plain TCP to loopback only; else the
    fleet folder's ``robot.json5`` (:func:`fleet_folder`), over TLS.
    """
    if config_file:
        if insecure_loopback:
            raise ValueError("--insecure-loopback is for a fleet without keys: drop it (--fleet-config has them)")
        return endpoint, config_file
    if insecure_loopback:
        if endpoint is None or not is_plain(endpoint):
            raise ValueError(f"--insecure-loopback takes a plain --fleet tcp/127.0.0.1:{DEFAULT_PORT}")
        problem = plain_problem(endpoint, "--fleet")
        if problem:
            raise ValueError(problem)
        return endpoint, None
    folder = fleet_folder()
    if endpoint is not None and is_plain(endpoint):
        raise ValueError(f"--fleet {endpoint}: the fleet link is mutual TLS: join with tls/STATION:{DEFAULT_PORT} "
                         f"and the keys the station's enrolment gives (in {folder}, or --fleet-config FILE); "
                         f"for plain TCP on this computer only, add --insecure-loopback (any program on it could "
                         f"then command the robot)")
    config = folder / ROBOT_CONFIG
    if not config.is_file():
        raise ValueError(f"this robot has no keys to join the fleet: copy the enrolment 'beastbt station' prints "
                         f"(its robot/ folder) to {folder}/ on this robot, or give --fleet-config FILE; for plain TCP "
                         f"on this computer only, 'beastbt {command} --insecure-loopback --fleet "
                         f"tcp/127.0.0.1:{DEFAULT_PORT}'")
    return endpoint, str(config)


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
        config = zenoh.Config.from_file(str(path))
        _beside(config, path)
        return config
    except Exception as exc:  # noqa: BLE001 - zenoh says what is wrong in its own words
        text = str(exc).split(" at /")[0]  # not where in zenoh's own source it was found
        where = re.search(r"line: (\d+), column: (\d+)", text) or re.search(r"--> (\d+):(\d+)", text)
        position = Position(int(where[1]), int(where[2])) if where else Position(1, 1)
        message = re.sub(r"\s+", " ", text.split("location:")[0]).strip(" ,")
        raise InvalidInput([Problem(str(path), position, f"not a Zenoh configuration: {message[:300]}",
                                    "a standard Zenoh JSON5 configuration (zenoh.io: Configuration)")]) from None


def _beside(config: Any, path: Path) -> None:
    """Find the relative TLS files of the configuration read from ``path`` beside it (not in the current folder)."""
    for name in TLS_FILES:
        key = f"transport/link/tls/{name}"
        value = json.loads(config.get_json(key))
        if isinstance(value, str) and value and not Path(value).is_absolute():
            _insert(config, key, str(path.resolve().parent / value))


def _insert(config: Any, key: str, value: Any) -> None:
    config.insert_json5(key, json.dumps(value))


def robot_config(options: FleetOptions) -> Any:
    """The Zenoh configuration of a robot (a peer connecting to the station; see the module docstring)."""
    import zenoh
    if options.config_file:
        config = _load(options.config_file, "--fleet-config")
    else:
        problem = plain_problem(options.endpoint, "--fleet")
        if problem:  # whoever asks: plain TCP without keys stays on this computer
            raise InvalidInput([Problem("--fleet", Position(), problem, "beastbt station prints a robot's enrolment")])
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
    """The Zenoh configuration of the station: a router listening on ``listen``; without ``config_file`` (plain TCP),
    on loopback only (InvalidInput otherwise)."""
    import zenoh
    if config_file:
        config = _load(config_file, "--fleet-config")
    else:
        problem = plain_problem(listen, "--listen")
        if problem:
            raise InvalidInput([Problem("--listen", Position(), problem,
                                        "without --insecure-loopback, 'beastbt station' makes the keys itself")])
        config = zenoh.Config()
        _insert(config, "mode", "router")
        _insert(config, "scouting/multicast/enabled", False)
        _insert(config, "scouting/gossip/enabled", False)
        _insert(config, "connect/endpoints", [])
    if listen:
        _insert(config, "listen/endpoints", [listen])
    return config


__all__ = ["FleetOptions", "parse_endpoint", "robot_config", "station_config", "DEFAULT_PORT", "fleet_folder",
           "robot_link", "plain_problem", "is_plain", "endpoint_host", "ROBOT_CONFIG", "INSECURE_ROBOT_WARNING"]
