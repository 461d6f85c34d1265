"""What the fleet's tests share: a free loopback port, polling with a deadline, and one HTTP request."""

from __future__ import annotations

import json
import socket
import time
import urllib.error
import urllib.request
from typing import Any, Callable, Optional


def free_port() -> int:
    """A TCP port free on loopback now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(check: Callable[[], Any], timeout_s: float, what: str, period_s: float = 0.02) -> Any:
    """Poll ``check`` every ``period_s`` until it returns something true, and return that; fail naming ``what``."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = check()
        if value:
            return value
        time.sleep(period_s)
    raise AssertionError(f"not within {timeout_s} s: {what}")


def http(method: str, url: str, body: Optional[bytes] = None, content_type: str = "application/json",
         headers: Optional[dict] = None, timeout_s: float = 40.0) -> tuple[int, Any]:
    """(status, JSON) of one request; ``headers`` replace the default ``Content-Type`` header when given."""
    request = urllib.request.Request(url, data=body, method=method,
                                     headers=headers if headers is not None else {"Content-Type": content_type})
    try:
        with urllib.request.urlopen(request, timeout=timeout_s) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())
