"""The guard of a browser-facing server on this computer: Host, token, Origin, JSON-only (the console's and studio's).

What a page on another site, open in the same browser, cannot do (the checks
of :meth:`WebGuard.refusal`, in order; see docs/console.md, Security):

1. ``Host``: a server bound to loopback without a token answers only to
   ``localhost``, ``127.0.0.1``, ``[::1]`` or its bound address (any port);
   anything else (a DNS-rebinding page) gets 403. With a token any name is
   served: a rebinding page does not have the token.
2. ``Origin``: a request that a browser marks as coming from another page
   (``Origin`` not ``http://`` + its ``Host``, or ``Sec-Fetch-Site:
   cross-site``/``same-site``) gets 403, the WebSocket upgrades included,
   unless it carries the token itself (``?token=`` or ``Bearer``; the cookie
   does not count: it goes with same-site requests from other ports).
3. A request that acts (anything but GET/HEAD/OPTIONS) without the token
   itself must be ``Content-Type: application/json``: a form or
   ``text/plain`` POST (what a page can send without asking the server first)
   gets 403. A client with no ``Origin`` (curl, a script) is not a browser and
   is accepted on loopback.

Off loopback (or when the token is required on loopback too) every request
needs the token: ``?token=``, an ``Authorization: Bearer`` header, or the
cookie the page gets. Without it: 401.
"""

from __future__ import annotations

import hmac
import secrets
from dataclasses import dataclass
from typing import Optional

from aiohttp import web

from beastbt.live.endpoint import host_allowed, is_loopback, same_origin


@dataclass(frozen=True)
class GuardWords:
    """What the refusals call the server and how the user gets past them (so each server's messages fit it)."""

    what: str = "console"
    """The server's name in the messages: ``console`` or ``studio``."""
    token_option: str = "--console-token always"
    """The option that makes the token required on loopback too (behind a proxy or a tunnel)."""
    started: str = "the run started"
    """When the address with the token was printed."""
    acting: str = "a control"
    """What a request that acts is called."""


class WebGuard:
    """Decides whether one request may be served (see the module docstring); holds the token."""

    def __init__(self, host: str, token: Optional[str] = None, require_token: Optional[bool] = None,
                 cookie: str = "beastbt_console_token", words: GuardWords = GuardWords()) -> None:
        self.host = host
        self.needs_token = not is_loopback(host) if require_token is None else bool(require_token)
        """Every request needs the token: off loopback always, on loopback when required."""
        self.token = token or secrets.token_urlsafe(18)
        self.cookie = cookie
        self.words = words

    @staticmethod
    def error(status: int, message: str) -> web.Response:
        """A JSON ``{error}`` answer."""
        return web.json_response({"error": message}, status=status)

    def refusal(self, request: web.Request, body_types: tuple[str, ...] = ("application/json",)
                ) -> Optional[web.Response]:
        """The answer to a request the server must not serve, or None when it may.

        ``body_types`` are the content types a request that acts may have without the token (JSON only by default:
        a server may add others that are not a form's or ``text/plain``, which any page can send unasked).
        """
        w = self.words
        host = request.headers.get("Host")
        if not self.needs_token and not host_allowed(host, self.host):
            shown, bound = (host or "")[:80], ("" if self.host in ("127.0.0.1", "localhost", "::1") else
                                               f", {self.host}")
            return self.error(403, f"this {w.what} answers to localhost, 127.0.0.1 or [::1]{bound} only, not Host "
                                   f"'{shown}': "
                                   f"a page that reaches it under another name (DNS rebinding) may not use it; behind "
                                   f"a proxy or a tunnel with another name, run with {w.token_option}")
        if self.needs_token and not self.has_token(request):
            return self.error(401, f"this {w.what} needs its token: open the address printed when {w.started} "
                                   f"(it ends in ?token=...)")
        if self.explicit_token(request):
            return None  # no other page has the token: whatever sent it is the operator's
        origin = request.headers.get("Origin")
        if origin is not None and not same_origin(origin, host):
            return self.error(403, f"a request from the page '{origin[:80]}' is refused: only the {w.what}'s own "
                                   f"page (or a client with the token) may use it")
        site = request.headers.get("Sec-Fetch-Site", "")
        acts = request.method not in ("GET", "HEAD") or request.headers.get("Upgrade", "").lower() == "websocket"
        # a plain GET from another page (a link, a bookmark page) may load it: it cannot read it
        if acts and site in ("cross-site", "same-site"):
            return self.error(403, f"a request from another page ({site}) is refused: only the {w.what}'s own page "
                                   f"(or a client with the token) may use it")
        if request.method not in ("GET", "HEAD", "OPTIONS") and request.content_type not in body_types:
            return self.error(403, f"{w.acting} needs Content-Type: application/json (this one is "
                                   f"'{request.content_type[:60]}'), as the {w.what}'s page sends, or the token: a "
                                   f"page on another site can send a form or text/plain, never JSON without asking")
        return None

    def explicit_token(self, request: web.Request) -> bool:
        """The token sent in the request itself (``?token=``, ``Authorization: Bearer``), not by the cookie jar."""
        given = [request.query.get("token", "")]
        auth = request.headers.get("Authorization", "")
        if auth.startswith("Bearer "):
            given.append(auth[7:].strip())
        return any(g and hmac.compare_digest(g.encode(), self.token.encode()) for g in given)

    def has_token(self, request: web.Request) -> bool:
        """The token in the request itself or in the cookie the page got."""
        cookie = request.cookies.get(self.cookie, "")
        return self.explicit_token(request) or bool(cookie) and hmac.compare_digest(cookie.encode(),
                                                                                     self.token.encode())

    def set_cookie_if_given(self, request: web.Request, response: web.StreamResponse) -> None:
        """The page takes the token out of its address at once; from then on this cookie carries it."""
        if self.needs_token and self.explicit_token(request) and request.path in ("/", "/index.html"):
            response.set_cookie(self.cookie, self.token, httponly=True, samesite="Strict", path="/")


__all__ = ["GuardWords", "WebGuard"]
