"""Test support for the ROS 2 link: a plain Zenoh peer on loopback that sees the graph's liveliness tokens."""

from __future__ import annotations

import json
from typing import Any, Callable, Optional


def peer_with_tokens(port: int, wanted: Callable[[list[str]], bool] = bool,
                     key: str = "@ros2_lv/**") -> Optional[tuple[Any, list[str]]]:
    """(a Zenoh peer session connected to ``tcp/127.0.0.1:PORT``, the liveliness tokens on ``key`` it sees: rmw_zenoh's
    by default, ``@/*/@ros2_lv/**`` for the DDS bridge's) once the tokens are ``wanted``; None (nothing left open)
    while the port does not listen yet or the tokens are not there."""
    import zenoh
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    try:
        session = zenoh.open(conf)
    except Exception:  # noqa: BLE001 - not listening yet
        return None
    tokens = [str(r.ok.key_expr) for r in session.liveliness().get(key, timeout=1.0) if r.ok is not None]
    if not wanted(tokens):
        session.close()
        return None
    return session, tokens
