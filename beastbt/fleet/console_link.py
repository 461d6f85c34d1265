"""The link from the station's page to a robot's own console: only ``http(s)://`` on the robot's own address.

A robot says where its operator console is (``console_url`` in its state), and
the station's page links its name there. A robot's word is not enough for a
link people click: a rogue or broken robot could send them to any site. So the
station checks it against what it knows itself, the address the robot's Zenoh
session comes from (:func:`link_addresses`, from the router's own links, found
by the Zenoh id the robot puts in its state):

* ``http://`` or ``https://`` only, with no user or password in it;
* on an IP address: that address must be the robot's;
* on a name (``http://beast-01:8080/``, a console on ``0.0.0.0``): the station
  asks no DNS, it puts the robot's address in the name's place;
* on the robot's loopback (``localhost``, ``127.0.0.1``) while the robot is elsewhere:
  not reachable from here, dropped.

Anything else is dropped, with the reason (``console_url_problem`` in
``GET /api/robots``). Only the scheme, the address, the port and the path are
kept (no query, no fragment).
"""

from __future__ import annotations

import ipaddress
import re
import urllib.parse
from typing import Any, Optional

URL_MAX = 2000
"""The longest ``console_url`` taken (characters)."""
_LINK = re.compile(r"[a-z0-9]+/(?P<addr>\[[0-9a-fA-F:.%a-z]+\]|[^/:\[\]#?]+):\d+")


def link_addresses(links: Any) -> dict[str, str]:
    """Zenoh id -> the address its link comes from (``dst`` of the router's links: ``tls/192.168.1.23:51234``)."""
    out = {}
    for link in links:
        m = _LINK.match(str(getattr(link, "dst", "")))
        if m:
            out[str(link.zid)] = m["addr"].strip("[]").split("%")[0]
    return out


def _ip(text: str) -> Optional[Any]:
    try:
        ip = ipaddress.ip_address(text)
    except ValueError:
        return None
    mapped = getattr(ip, "ipv4_mapped", None)  # ::ffff:10.0.0.5 is 10.0.0.5
    return mapped or ip


def robot_console_url(url: Any, address: Optional[str]) -> tuple[Optional[str], Optional[str]]:
    """(the URL the station links, or None; why it links none, or None) for a robot's ``console_url`` and the address
    its Zenoh session comes from (None: not known). See the module docstring."""
    if url is None:
        return None, None
    if not isinstance(url, str) or not url or len(url) > URL_MAX:
        return None, "its console_url is not a URL"
    try:
        parts = urllib.parse.urlsplit(url)
        port = parts.port
        host = parts.hostname or ""
    except ValueError:
        return None, "its console_url is not a URL"
    if parts.scheme not in ("http", "https"):
        return None, f"its console_url is not http:// or https:// ({parts.scheme[:20] or 'no scheme'}:)"
    if parts.username is not None or parts.password is not None or not host:
        return None, "its console_url names a user or no host"
    if address is None:
        return None, "the station does not know the robot's address (no Zenoh link of its own), so it cannot check " \
                     "its console_url"
    robot = _ip(address)
    asked = _ip(host)
    local = host == "localhost" or (asked is not None and asked.is_loopback)
    if local and not (robot is not None and robot.is_loopback):
        return None, f"its console listens on the robot's loopback ({host}) only: not reachable from the station"
    if asked is not None and not local and asked != robot:
        return None, f"its console_url is on {host}, not on the robot's own address {address}"
    where = address if robot is None or robot.version == 4 else f"[{address}]"
    return f"{parts.scheme}://{where}" + (f":{port}" if port else "") + (parts.path or "/"), None


__all__ = ["robot_console_url", "link_addresses", "URL_MAX"]
