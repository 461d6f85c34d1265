"""The operator console's web server (aiohttp, in a thread of its own): the page, the API, the live pushes.

The contract (tests and other tools rely on it):

* ``GET /api/state``: the run's state (:mod:`beastbt.live.console_state`);
  ``GET /api/map``: the map's fixed layers and the trail so far.
* ``WS /api/ws``: the state, pushed at least 5 times a second; the final state
  is always sent before the socket closes at the end of the run.
* ``WS /api/video``: the camera as binary JPEG messages, or H.264 to a page that
  says it decodes it (:mod:`beastbt.live.console_video`).
* ``POST /api/pause``, ``/api/resume``, ``/api/abort``, ``/api/estop``,
  ``/api/estop/reset``, ``/api/answer`` (``{id, choice}``), ``/api/teleop``
  (``{linear, angular, deadman}``); live tuning (:mod:`beastbt.live.tuning`): ``GET /api/tuning``
  (the knobs), ``POST /api/tuning`` (``{name, value}``), ``/api/tuning/reset``, ``/api/tuning/save``. Each answers ``{ok: true, ...}``, or a 4xx
  with ``{error}`` when it cannot be done (409: not now, 400: a bad request).
* ``GET /api/photos``: the run's photos so far, ``{photos: [{name, time_s, url}]}``; ``GET /api/photos/NAME.jpg``:
  one photo's JPEG, as saved in the run folder (:mod:`beastbt.live.console_photos`); any other name is a 404.
* Off loopback (or with ``--console-token always``) every request needs the
  run's token (printed once at start): ``?token=``, an ``Authorization:
  Bearer`` header, or the cookie the page gets. Without it: 401. A server
  bound to loopback needs none by default.

What a page on another site, open in the same browser, cannot do (the checks
of :class:`beastbt.live.web_guard.WebGuard`, shared with the studio, in order; see docs/console.md, Security):

1. ``Host``: a console bound to loopback without a token answers only to
   ``localhost``, ``127.0.0.1``, ``[::1]`` or its bound address (any port);
   anything else (a DNS-rebinding page) gets 403. With a token any name is
   served: a rebinding page does not have the token.
2. ``Origin``: a request that a browser marks as coming from another page
   (``Origin`` not ``http://`` + its ``Host``, or ``Sec-Fetch-Site:
   cross-site``/``same-site``) gets 403, the WebSocket upgrades included,
   unless it carries the token itself (``?token=`` or ``Bearer``; the cookie
   does not count: it goes with same-site requests from other ports).
3. A control (every POST) without the token itself must be ``Content-Type:
   application/json``: a form or ``text/plain`` POST (what a page can send
   without asking the server first) gets 403. A client with no ``Origin``
   (curl, a script) is not a browser and is accepted on loopback.
4. A control's body is at most 4 kB of strict JSON (:func:`parse_control_body`):
   anything else is a 4xx with ``{error}``, never a 500.

Every answer carries ``Referrer-Policy: no-referrer``, ``nosniff``, no
framing (``X-Frame-Options: DENY``, CSP ``frame-ancestors 'none'``) and the
API ``Cache-Control: no-store``.

Nothing a request does can end the run by accident: every handler's error
becomes a JSON answer, and the run's state is only touched on the tick thread
(:mod:`beastbt.live.console_control`), except the e-stop, which is safe from
any thread.
"""

from __future__ import annotations

import asyncio
import socket
import threading
from importlib import resources
from typing import Any, Awaitable, Callable, Optional

from aiohttp import WSMsgType, web

from beastbt.live.console_control import (CONTROL_MAX_BYTES, Refused, check_answer_body, check_teleop_body,
                                          parse_control_body)
from beastbt.live.console_photos import PhotoShelf
from beastbt.live.endpoint import SECURITY_HEADERS, is_loopback
from beastbt.live.server_thread import start_loop_thread
from beastbt.live.tuning import check_tune_body
from beastbt.live.web_guard import WebGuard
from beastbt.live.console_state import state_json  # noqa: F401 - part of this module's names
from beastbt.live.console_video import ConsoleVideo

PUSH_PERIOD_S = 0.1
"""The state is pushed to every WebSocket at least this often (s): 10 a second."""
CONTROL_TIMEOUT_S = 2.0
"""How long a control waits for the tick thread before the answer is 503 (s)."""
SAVE_TIMEOUT_S = 6.0
"""How long saving the tuning may take (s): two controls on the tick thread and the profile's file written between."""
TOKEN_COOKIE = "beastbt_console_token"
CONTENT_SECURITY_POLICY = ("default-src 'self'; script-src 'self'; img-src 'self' data: blob:; "
                           "media-src blob:; connect-src 'self'; object-src 'none'; base-uri 'none'; "
                           "form-action 'none'; frame-ancestors 'none'")
"""The page loads only its own files and talks only to its own server; no other page may frame it (the e-stop
and the stick cannot be clickjacked). No inline script runs and no string is evaluated as code. Media only from
the page's own blobs: the H.264 it plays through MSE (console_page/console.js)."""
WS_PATHS = ("/api/ws", "/api/video")
PAGE_FILES = {"console.js": "application/javascript", "console.css": "text/css", "favicon.svg": "image/svg+xml"}
"""The page's own files, shipped in the package (no CDN: it works offline in a field)."""


def _page(name: str) -> bytes:
    return resources.files("beastbt.live").joinpath("console_page", name).read_bytes()


def _read_file(path: str) -> bytes:
    with open(path, "rb") as f:
        return f.read()


def _error(status: int, message: str) -> web.Response:
    return web.json_response({"error": message}, status=status)


class ConsoleServer:
    """The console of one run, served on ``host:port`` until :meth:`close` (see the module docstring)."""

    def __init__(self, state: Any, controls: Any, video: ConsoleVideo, map_source: Callable[[], dict],
                 host: str = "127.0.0.1", port: int = 0, token: Optional[str] = None,
                 require_token: Optional[bool] = None) -> None:
        self.state = state
        """Gives the last state as JSON text: ``latest_json()`` -> ``(seq, text)`` (the run serialised it)."""
        self.controls = controls
        """Takes the controls: ``submit(name, body)`` -> a Future of the result (raises Refused)."""
        self.video = video
        self.map_source = map_source
        self.host = host
        self.requested_port = port
        self.guard = WebGuard(host, token, require_token, cookie=TOKEN_COOKIE)
        """The checks of every request (Host, token, Origin, JSON): :mod:`beastbt.live.web_guard`."""
        self.needs_token = self.guard.needs_token
        """Every request needs the token: off loopback always, on loopback with ``--console-token always``."""
        self.token = self.guard.token
        self.port = port
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self._thread: Optional[threading.Thread] = None
        self._runner: Optional[web.AppRunner] = None
        self._ending: Optional[asyncio.Event] = None
        self._handlers: set[asyncio.Task] = set()
        self.requests = 0
        self.photos = PhotoShelf()
        """The photos the run saved, by file name: the only files ``/api/photos/`` serves."""
        self.on_viewers: Optional[Callable[[int], None]] = None
        """Called with the number of video viewers each time it changes (on the server's thread), or None."""

    # -- life ------------------------------------------------------------------------
    def start(self) -> "ConsoleServer":
        """Bind and serve in a daemon thread; raises OSError when the address cannot be bound."""
        self._thread, self._loop = start_loop_thread(self._bind, "beastbt-console")
        return self

    async def _bind(self) -> None:
        self._ending = asyncio.Event()
        app = web.Application(middlewares=[self._guard], client_max_size=CONTROL_MAX_BYTES)
        app.on_response_prepare.append(self._headers)
        app.router.add_get("/", self._index)
        app.router.add_get("/index.html", self._index)
        app.router.add_get("/static/{name}", self._static)
        app.router.add_get("/favicon.ico", self._favicon)  # asked for by browsers that do not read the page's link
        app.router.add_get("/api/state", self._get_state)
        app.router.add_get("/api/map", self._get_map)
        app.router.add_get("/api/ws", self._ws_state)
        app.router.add_get("/api/video", self._ws_video)
        for name in ("pause", "resume", "abort", "answer", "teleop"):
            app.router.add_post(f"/api/{name}", self._control(name))
        app.router.add_get("/api/photos", self._photo_list)
        app.router.add_get("/api/photos/{name}", self._photo)
        app.router.add_get("/api/tuning", self._tuning)
        app.router.add_post("/api/tuning", self._control("tune"))
        app.router.add_post("/api/tuning/reset", self._control("tune_reset"))
        app.router.add_post("/api/tuning/save", self._tuning_save)
        app.router.add_post("/api/estop", self._estop)
        app.router.add_post("/api/estop/reset", self._estop_reset)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.requested_port, reuse_address=True)
        await site.start()
        server = site._server  # the bound port when 0 was asked for
        sockets = getattr(server, "sockets", None) or []
        if sockets:
            self.port = sockets[0].getsockname()[1]

    @property
    def url(self) -> str:
        """The page's address, with the token when one is needed."""
        host = self.host
        if host in ("0.0.0.0", "::", ""):
            host = socket.gethostname()
        elif ":" in host:
            host = f"[{host}]"
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.needs_token else "")

    def close(self, timeout_s: float = 3.0) -> None:
        """Send every viewer the final state, close their sockets and stop serving."""
        loop = self._loop
        if loop is None or not loop.is_running():
            return
        future = asyncio.run_coroutine_threadsafe(self._shutdown(), loop)
        try:
            future.result(timeout_s)
        except Exception:  # noqa: BLE001 - closing must finish whatever happened
            pass
        loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(timeout_s)

    async def _shutdown(self) -> None:
        assert self._ending is not None
        self._ending.set()  # every socket's handler sends what it owes (the final state) and closes
        if self.video is not None:
            self.video.wake_viewers()  # the video senders wait for a frame: they look at the end now
        handlers = [t for t in self._handlers if not t.done()]
        if handlers:
            await asyncio.wait(handlers, timeout=2.0)
        if self._runner is not None:
            await self._runner.cleanup()

    # -- the guard: host, token, origin, content type; errors as JSON ------------------------------
    @web.middleware
    async def _guard(self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
                     ) -> web.StreamResponse:
        self.requests += 1
        refusal = self._refusal(request)
        if refusal is not None:
            return refusal
        try:
            response = await handler(request)
        except web.HTTPException as exc:
            if exc.status < 400:
                raise
            return _error(exc.status, exc.reason or "bad request")
        except Refused as exc:
            return _error(exc.status, str(exc))
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # noqa: BLE001 - never a traceback, never the run
            return _error(500, f"the console could not answer: {type(exc).__name__}")
        self.guard.set_cookie_if_given(request, response)
        return response

    def _refusal(self, request: web.Request) -> Optional[web.Response]:
        """The answer to a request the console must not serve (see the module docstring), or None."""
        return self.guard.refusal(request, self.body_types(request))

    def body_types(self, request: web.Request) -> tuple[str, ...]:
        """The content types a POST to this path may have without the token: JSON only, for every control
        (each one a browser sends only after asking the server; a server built on this one may add others
        that are not a form's or ``text/plain``)."""
        return ("application/json",)

    def _explicit_token(self, request: web.Request) -> bool:
        """The token sent in the request itself (``?token=``, ``Authorization: Bearer``), not by the cookie jar."""
        return self.guard.explicit_token(request)

    async def _headers(self, request: web.Request, response: web.StreamResponse) -> None:
        """Every answer, the refusals and the WebSocket upgrades included: see :data:`SECURITY_HEADERS`."""
        for name, value in SECURITY_HEADERS.items():
            response.headers.setdefault(name, value)
        response.headers.setdefault("Content-Security-Policy", CONTENT_SECURITY_POLICY)
        if request.path.startswith("/api/"):
            response.headers["Cache-Control"] = "no-store"

    # -- the page ------------------------------------------------------------------------
    async def _index(self, request: web.Request) -> web.Response:
        return web.Response(body=_page("index.html"), content_type="text/html", charset="utf-8",
                            headers={"Cache-Control": "no-cache"})

    async def _static(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name not in PAGE_FILES:
            return _error(404, f"no file '{name}'")
        return web.Response(body=_page(name), content_type=PAGE_FILES[name], headers={"Cache-Control": "no-cache"})

    async def _favicon(self, request: web.Request) -> web.Response:
        return web.Response(body=_page("favicon.svg"), content_type=PAGE_FILES["favicon.svg"],
                            headers={"Cache-Control": "max-age=86400"})

    # -- state -----------------------------------------------------------------------------
    def _state_json(self) -> str:
        """The last state as JSON text, as the run serialised it (this process never parses it)."""
        return self.state.latest_json()[1]

    async def _get_state(self, request: web.Request) -> web.Response:
        return web.Response(text=self._state_json(), content_type="application/json")

    async def _get_map(self, request: web.Request) -> web.Response:
        return web.json_response(self.map_source())

    async def _photo_list(self, request: web.Request) -> web.Response:
        return web.json_response({"photos": self.photos.listing()})

    async def _photo(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        path = self.photos.path_of(name)
        if path is None:
            return _error(404, f"no photo '{name[:80]}' in this run: GET /api/photos lists them")
        try:
            data = await asyncio.get_running_loop().run_in_executor(None, _read_file, path)
        except OSError as exc:
            return _error(404, f"the photo '{name}' cannot be read: {exc.strerror or exc}")
        return web.Response(body=data, content_type="image/jpeg")

    async def _ws_state(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=10.0)
        await ws.prepare(request)
        task = asyncio.current_task()
        assert self._ending is not None and task is not None
        self._handlers.add(task)
        reader = asyncio.ensure_future(self._drain(ws))
        try:
            while not self._ending.is_set() and not ws.closed and not reader.done():
                await ws.send_str(self._state_json())
                # A plain timer: the end is noticed within one period (waiting on the end's event with a timeout
                # made a task and a timer ten times a second).
                await asyncio.sleep(PUSH_PERIOD_S)
            if self._ending.is_set() and not ws.closed:
                await ws.send_str(self._state_json())  # the final state, always, before the close
                await ws.close(message=b"the run has ended")
        except (ConnectionResetError, RuntimeError):
            pass
        finally:
            reader.cancel()
            self._handlers.discard(task)
        return ws

    async def _drain(self, ws: web.WebSocketResponse, told: Optional[Callable[[str], None]] = None) -> None:
        async for msg in ws:  # the page sends nothing it needs answered; this notices a closed tab
            if msg.type in (WSMsgType.CLOSE, WSMsgType.ERROR):
                break
            if told is not None and msg.type == WSMsgType.TEXT and len(msg.data) <= 1024:
                told(msg.data)  # the video page's word on what it decodes

    async def _ws_video(self, request: web.Request) -> web.WebSocketResponse:
        # No permessage-deflate, though every browser offers it: JPEG and H.264 do not shrink, and aiohttp would
        # deflate each frame on an executor thread (a thread woken per frame, for nothing).
        ws = web.WebSocketResponse(heartbeat=10.0, compress=False)
        await ws.prepare(request)
        task = asyncio.current_task()
        assert task is not None
        self._handlers.add(task)
        video = self.video
        feed = video.feed()  # JPEG, or H.264 once the page says it decodes it (console_video.ViewerFeed)
        loop = asyncio.get_running_loop()
        video.viewers += 1
        self._viewers_changed()
        assert self._ending is not None
        reader = asyncio.ensure_future(self._drain(ws, feed.hello))
        # Woken on this loop when a frame is ready (from the thread that made it), when the page goes, at the end.
        wake = asyncio.Event()

        def waker() -> None:
            # Set (and not yet cleared below) means the sender will look again anyway: no second wake-up.
            if not wake.is_set():
                try:
                    loop.call_soon_threadsafe(wake.set)
                except RuntimeError:  # the loop has stopped: nobody waits any more
                    pass

        video.add_waker(waker)
        reader.add_done_callback(lambda _: wake.set())
        try:
            while not self._ending.is_set() and not ws.closed and not reader.done():
                wake.clear()  # before looking: a frame made after this line wakes the wait below
                message = feed.next_message(0.0)
                if message is not None:
                    await ws.send_bytes(message)
                elif not feed.has_newer():  # (a unit skipped while waiting for a keyframe: the next may be in)
                    await wake.wait()
        except (ConnectionResetError, RuntimeError):
            pass
        finally:
            video.remove_waker(waker)
            reader.cancel()
            feed.close()
            video.viewers -= 1
            self._viewers_changed()
            self._handlers.discard(task)
            if not ws.closed:
                await ws.close(message=b"the run has ended")
        return ws

    def _viewers_changed(self) -> None:
        """Tell :attr:`on_viewers` the number of video viewers now (a failing listener never breaks the video)."""
        listener = self.on_viewers
        if listener is not None:
            try:
                listener(self.video.viewers)
            except Exception:  # noqa: BLE001 - the run's end closes the pipe it writes to
                pass

    # -- controls ------------------------------------------------------------------------
    async def _body(self, request: web.Request) -> dict:
        try:
            raw = await request.read()
        except web.HTTPRequestEntityTooLarge:
            raise Refused(413, f"the body is over {CONTROL_MAX_BYTES} bytes: a control is a small JSON object") \
                from None
        return parse_control_body(raw)

    def _control(self, name: str) -> Callable[[web.Request], Awaitable[web.Response]]:
        async def handle(request: web.Request) -> web.Response:
            body = await self._body(request)
            if name == "teleop":
                body = check_teleop_body(body)
            elif name == "answer":
                body = check_answer_body(body)
            elif name == "tune":
                body = check_tune_body(body)
            return await self._answer(name, body)
        return handle

    async def _tuning(self, request: web.Request) -> web.Response:
        return await self._answer("tuning", {})

    async def _tuning_save(self, request: web.Request) -> web.Response:
        await self._body(request)  # a body, if any, must still be a control's (strict JSON, 4 kB)
        return await self._answer("tune_save", {}, SAVE_TIMEOUT_S)

    async def _estop(self, request: web.Request) -> web.Response:
        return await self._answer("estop", {})

    async def _estop_reset(self, request: web.Request) -> web.Response:
        return await self._answer("estop_reset", {})

    async def _answer(self, name: str, body: dict, timeout_s: float = CONTROL_TIMEOUT_S) -> web.Response:
        future = self.controls.submit(name, body)
        try:
            outcome = await asyncio.wait_for(asyncio.wrap_future(future), timeout_s)
        except asyncio.TimeoutError:
            return _error(503, f"the run did not take '{name}' within {timeout_s:g} s")
        return web.json_response({"ok": True, **outcome})


__all__ = ["ConsoleServer", "is_loopback", "state_json", "PUSH_PERIOD_S"]
