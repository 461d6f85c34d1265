"""Where a live server listens (``[HOST:]PORT``), a frame size (``WxH``), and the checks a browser-facing server makes.

Light (the standard library only), for the command line and for both web
servers (the console and ``--stream``). The checks are what keeps a page on
another site, open in the same browser, from using a server on this computer:

* :func:`host_allowed`: the ``Host`` header of a server bound to loopback must
  name loopback (``localhost``, ``127.0.0.1``, ``[::1]`` or the bound address,
  any port). A DNS-rebinding page reaches 127.0.0.1 under its own name
  (``Host: evil.example``), so this refuses it.
* :func:`same_origin`: the ``Origin`` a browser sends names the page that made
  the request; it must be the server itself (``http://`` + the ``Host`` header).
* :data:`SECURITY_HEADERS`: sent with every answer (no referrer, no sniffing, no framing).
"""

from __future__ import annotations

import ipaddress
import socket
from typing import Optional
from urllib.parse import urlsplit

SECURITY_HEADERS = {
    "Referrer-Policy": "no-referrer",
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Cross-Origin-Resource-Policy": "same-origin",
    "Cross-Origin-Opener-Policy": "same-origin",
}
"""Headers on every answer: the address (and any token in it) never leaks as a referrer, content is not
sniffed into script, no other site can frame the page (clickjacking the e-stop or the stick) or embed what it serves."""
LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})
"""Host names that always mean this computer (a browser never asks DNS for them)."""


def parse_endpoint(text: str, option: str = "--stream") -> tuple[str, int]:
    """``PORT``, ``:PORT`` or ``HOST:PORT`` -> (host, port); the host defaults to 127.0.0.1.

    ``option`` names the command-line option in the error message.
    """
    text = str(text).strip()
    host, sep, port = text.rpartition(":")
    if not sep:
        host = ""
    host = host.strip("[]") or "127.0.0.1"
    try:
        number = int(port)
    except ValueError:
        raise ValueError(f"{option} takes [HOST:]PORT such as 8080 or 0.0.0.0:8080, not '{text}'") from None
    if not 0 <= number <= 65535:
        raise ValueError(f"{option} port must be 0..65535, not {number}")
    return host, number


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``: only this computer can reach a server bound there."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def parse_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` (``640x480``) -> (width, height) in pixels."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise ValueError(f"--stream-size takes WIDTHxHEIGHT such as 640x480, not '{text}'") from None
    return w, h


def host_name(header: Optional[str]) -> Optional[str]:
    """The host of a ``Host`` header (``name``, ``name:port``, ``[v6]:port``), lowercased; None when malformed."""
    if not header or any(c in header for c in "/?#@ \\"):
        return None
    try:
        parts = urlsplit("//" + header.strip())
        parts.port  # noqa: B018 - raises ValueError on a port that is not a number in 0..65535
    except ValueError:
        return None
    return parts.hostname or None


def host_allowed(header: Optional[str], bound_host: str) -> bool:
    """Whether a ``Host`` header names this server bound on loopback at ``bound_host`` (any port: a tunnel's differs).

    Accepted: ``localhost``, ``127.0.0.1``, ``[::1]`` (any loopback address written out) and the bound address
    itself. Any other name is a page
    that reached us through DNS rebinding (or a misdirected request). No ``Host`` at all (``None``: an
    HTTP/1.0 client) is accepted: every browser sends one, so it is never a page.
    """
    if header is None:
        return True
    name = host_name(header)
    if name is None:
        return False
    bound = bound_host.strip("[]").lower()
    return name in LOOPBACK_NAMES or name == bound or _loopback_literal(name)


def _loopback_literal(name: str) -> bool:
    """An IP address in 127.0.0.0/8 or ::1 written out (no DNS name: nothing to rebind)."""
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def host_on_network(header: Optional[str]) -> bool:
    """For a server bound off loopback without a token (``--stream 0.0.0.0:PORT``): ``Host`` is an IP address,
    ``localhost`` or this computer's own name (``beastbot``, ``beastbot.local``).

    A rebinding page shows its own DNS name, which is none of these. No ``Host`` at all is accepted, as by
    :func:`host_allowed`.
    """
    if header is None:
        return True
    name = host_name(header)
    if name is None:
        return False
    try:
        ipaddress.ip_address(name)
        return True
    except ValueError:
        pass
    own = socket.gethostname().lower()  # no DNS lookup here (getfqdn could wait seconds on a robot offline)
    return name in LOOPBACK_NAMES or name in (own, own.split(".")[0], own.split(".")[0] + ".local")


def same_origin(origin: Optional[str], host_header: Optional[str]) -> bool:
    """Whether an ``Origin`` header is this server's own page: ``http(s)://`` and exactly the ``Host`` it asked for.

    ``http://localhost:8080`` and ``http://127.0.0.1:8080`` are different origins, as for the browser.
    ``null`` (a sandboxed frame, a file) is never the server's own page.
    """
    if not origin or not host_header:
        return False
    try:
        parts = urlsplit(origin.strip())
    except ValueError:
        return False
    if parts.scheme not in ("http", "https") or parts.path not in ("", "/") or parts.query or parts.username:
        return False
    return parts.netloc.lower() == host_header.strip().lower()


__all__ = ["parse_endpoint", "parse_size", "is_loopback", "host_name", "host_allowed", "host_on_network",
           "same_origin", "SECURITY_HEADERS", "LOOPBACK_NAMES"]
