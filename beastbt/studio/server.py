"""The studio's web server (aiohttp): the page from ``beastbt/studio/page/`` and the JSON API of docs/studio.md.

Every request passes the guard the operator console uses
(:class:`beastbt.live.web_guard.WebGuard`: Host, token off loopback, Origin,
JSON-only for anything that acts). Every answer of ``/api/`` is JSON; an
error is ``{error}`` with a 4xx, never a traceback. The work that takes CPU
(validating, compiling, drawing, editing) runs in warm worker processes
(:mod:`beastbt.studio.work_pool`), killed when it takes too long, runs out of
memory or its client leaves: a text too large to check is a problem at its line
1, not a studio that hangs. Reading the folder and starting tries run on
daemon threads, so that SIGTERM ends the studio within 2 s whatever it does.
"""

from __future__ import annotations

import asyncio
import json
import mimetypes
import os
import signal
import socket
import threading
from pathlib import Path
from typing import Any, Awaitable, Callable, Optional

from aiohttp import web

from beastbt.core.resources import data_dir
from beastbt.live.endpoint import SECURITY_HEADERS
from beastbt.live.server_thread import start_loop_thread
from beastbt.live.web_guard import GuardWords, WebGuard
from beastbt.studio.files import FileRefused, StudioFolder
from beastbt.studio.work_pool import WORK_TIMEOUT_S, WORKER_MEMORY_BYTES, WorkPool, WorkRefused

DEFAULT_PORT = 8070
"""``beastbt studio`` listens on 127.0.0.1:8070 unless ``--listen`` says otherwise."""
MAX_BODY_BYTES = 2_500_000
"""A request's body is at most this many bytes (a file's text, JSON-quoted)."""
IO_THREADS = 4
"""At most this many folder listings, try starts and reports at once (each on a daemon thread)."""
SHUTDOWN_S = 0.5
"""When the studio ends, how long the requests still being answered get (s)."""
WORK_VERBS = {"validate": ("check", "checking"), "tree": ("compile", "compiling"), "map": ("draw", "drawing"),
              "edit": ("edit", "editing")}
"""What each worker job does, for the too-large answer."""
TOKEN_COOKIE = "beastbt_studio_token"
PAGE_DIR = Path(__file__).parent / "page"
"""The built page (shipped in the package; built with npm, see docs/studio.md)."""
CONTENT_SECURITY_POLICY = ("default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
                           "img-src 'self' data: blob: https://tile.openstreetmap.org; font-src 'self' data:; "
                           "worker-src 'self' blob:; "
                           "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'none'; "
                           "frame-ancestors 'none'")
"""The page loads only its own files and talks only to its own server. Monaco sets styles inline and runs its
language services in workers; no inline script runs and no string is evaluated as code. The map's online tiles
(off by default: the page works offline) come from OpenStreetMap when the user turns them on."""


class BadRequest(Exception):
    """A request the API refuses: ``status`` and the ``{error, ...}`` body."""

    def __init__(self, status: int, message: str, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.extra = extra


class StudioServer:
    """The studio on ``host:port`` for ``folder``: :meth:`start` serves in a thread, :meth:`serve` in this one."""

    def __init__(self, folder: str | os.PathLike, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 token: Optional[str] = None, require_token: Optional[bool] = None,
                 work_timeout_s: float = WORK_TIMEOUT_S, work_memory_bytes: int = WORKER_MEMORY_BYTES) -> None:
        self.folder = StudioFolder(Path(folder))
        self.host = host
        self.requested_port = port
        self.port = port
        self.guard = WebGuard(host, token, require_token, cookie=TOKEN_COOKIE,
                              words=GuardWords("studio", "--token always", "the studio started", "a request that "
                                                                                                  "acts"))
        self.pool = WorkPool(self.folder.root, timeout_s=work_timeout_s, memory_bytes=work_memory_bytes)
        self._io_slots: Optional[asyncio.Semaphore] = None
        from beastbt.studio.trial import Trials
        self.trials = Trials(self.folder)
        from beastbt.studio.mission_tests import TestRuns
        self.tests = TestRuns(self.folder, self.trials)
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self._thread: Optional[threading.Thread] = None
        self._runner: Optional[web.AppRunner] = None

    # -- life ------------------------------------------------------------------------
    def app(self) -> web.Application:
        """The aiohttp application: the guard, the page and the API."""
        app = web.Application(middlewares=[self._guard], client_max_size=MAX_BODY_BYTES)
        app.on_response_prepare.append(self._headers)
        r = app.router
        r.add_get("/api/files", self._list_files)
        r.add_get("/api/files/{path:.+}", self._get_file)
        r.add_put("/api/files/{path:.+}", self._put_file)
        r.add_get("/api/templates", self._list_templates)
        r.add_post("/api/templates/{name}", self._template)
        r.add_get("/api/robots", self._list_robots)
        r.add_post("/api/validate", self._json_work("validate"))
        r.add_post("/api/tree", self._json_work("tree"))
        r.add_post("/api/map", self._json_work("map"))
        r.add_post("/api/edit", self._json_work("edit"))
        r.add_post("/api/try", self._try)
        r.add_get("/api/try/{run_id}", self._try_state)
        r.add_post("/api/try/{run_id}/stop", self._try_stop)
        r.add_get("/api/try/{run_id}/report", self._try_report)
        r.add_get("/api/try/{run_id}/report/", self._try_report)
        r.add_get("/api/try/{run_id}/report/{name:.+}", self._try_report_asset)
        r.add_get("/api/try/{run_id}/console/{what:.+}", self._try_console)
        r.add_post("/api/try/{run_id}/console/{what:.+}", self._try_console)
        r.add_get("/api/tests", self._list_tests)
        r.add_post("/api/tests/new", self._new_test)
        r.add_post("/api/test", self._test)
        r.add_get("/api/test/{test_id}", self._test_state)
        r.add_post("/api/test/{test_id}/stop", self._test_stop)
        r.add_route("*", "/api/{rest:.*}", self._no_api)
        r.add_get("/schemas/{name:.+}", self._schema)
        r.add_get("/", self._page)
        r.add_get("/{name:.+}", self._page)
        app.on_cleanup.append(self._cleanup)
        return app

    async def _cleanup(self, app: web.Application) -> None:
        self.pool.close()
        self.trials.stop_all()
        self.tests.stop_all()

    def start(self) -> "StudioServer":
        """Bind and serve in a daemon thread; raises OSError when the address cannot be bound."""
        async def clean_up() -> None:
            if self._runner is not None:
                await self._runner.cleanup()

        self._thread, self._loop = start_loop_thread(self._bind, "beastbt-studio", after=clean_up)
        return self

    async def _bind(self) -> None:
        # the workers warm up (schemas, compiler, parts: about a second) while the page loads
        self.pool.start(asyncio.get_running_loop())
        self._io_slots = asyncio.Semaphore(IO_THREADS)
        self._runner = web.AppRunner(self.app(), access_log=None, handle_signals=False,
                                     shutdown_timeout=SHUTDOWN_S)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.requested_port, reuse_address=True)
        await site.start()
        sockets = getattr(site._server, "sockets", None) or []  # the bound port when 0 was asked for
        if sockets:
            self.port = sockets[0].getsockname()[1]

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop the runs it started, its workers, and serving."""
        self.pool.close()
        self.trials.stop_all()
        self.tests.stop_all()
        loop = self._loop
        if loop is not None and loop.is_running():
            loop.call_soon_threadsafe(loop.stop)
            if self._thread is not None:
                self._thread.join(timeout_s)

    def serve_forever(self, on_ready: Callable[[], None] = lambda: None) -> None:
        """Serve in this thread until Ctrl-C or SIGTERM (the command's way); the tries still running are stopped."""
        async def main() -> None:
            await self._bind()
            ending = asyncio.Event()
            try:
                # a service manager or a test ends the studio with SIGTERM: its tries must not outlive it
                asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, ending.set)
            except (NotImplementedError, RuntimeError):  # not on this platform, or not the main thread
                pass
            on_ready()
            try:
                await ending.wait()
            finally:
                # the workers first: a request waiting on one is answered at once, and nothing computes on;
                # the tries stop meanwhile
                self.pool.close()
                self.trials.begin_stop()
                for run in list(self.tests.runs.values()):
                    if run.process.poll() is None:
                        run.process.terminate()
                if self._runner is not None:
                    await self._runner.cleanup()
        try:
            asyncio.run(main())
        except KeyboardInterrupt:
            pass
        finally:
            self.pool.close()
            self.trials.stop_all()
            self.tests.stop_all()

    @property
    def url(self) -> str:
        """The page's address, with the token when one is needed."""
        host = self.host
        if host in ("0.0.0.0", "::", ""):
            host = socket.gethostname()
        elif ":" in host:
            host = f"[{host}]"
        return f"http://{host}:{self.port}/" + (f"?token={self.guard.token}" if self.guard.needs_token else "")

    # -- the guard and the headers -------------------------------------------------------------
    @web.middleware
    async def _guard(self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
                     ) -> web.StreamResponse:
        refusal = self.guard.refusal(request)
        if refusal is not None:
            return refusal
        try:
            response = await handler(request)
        except BadRequest as exc:
            return web.json_response({"error": str(exc), **exc.extra}, status=exc.status)
        except FileRefused as exc:
            body: dict[str, Any] = {"error": str(exc)}
            if exc.status == 409:
                body["disk_text"] = exc.disk_text
            return web.json_response(body, status=exc.status)
        except web.HTTPException as exc:
            if exc.status < 400:
                raise
            return WebGuard.error(exc.status, exc.reason or "bad request")
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # noqa: BLE001 - never a traceback to the page
            return WebGuard.error(500, f"the studio could not answer: {type(exc).__name__}: {str(exc)[:200]}")
        self.guard.set_cookie_if_given(request, response)
        return response

    async def _headers(self, request: web.Request, response: web.StreamResponse) -> None:
        for name, value in SECURITY_HEADERS.items():
            response.headers.setdefault(name, value)
        response.headers.setdefault("Content-Security-Policy", CONTENT_SECURITY_POLICY)
        if request.path.startswith("/api/"):
            response.headers["Cache-Control"] = "no-store"

    # -- the page ------------------------------------------------------------------------
    async def _page(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info.get("name", "") or "index.html"
        root = Path(os.path.realpath(PAGE_DIR))
        target = Path(os.path.realpath(root / name))
        if ".." in Path(name).parts or root not in target.parents or not target.is_file():
            if "." not in Path(name).name:  # a page address (no file suffix): the page itself
                target = root / "index.html"
            else:
                return WebGuard.error(404, f"no file '{name[:80]}' in the studio's page")
        if not target.is_file():
            return WebGuard.error(404, "the studio's page is not built: see docs/studio.md, Building the page")
        ctype = mimetypes.guess_type(target.name)[0] or "application/octet-stream"
        if target.suffix in (".js", ".mjs"):
            ctype = "application/javascript"
        return web.FileResponse(target, headers={"Content-Type": ctype, "Cache-Control": "no-cache"})

    async def _schema(self, request: web.Request) -> web.StreamResponse:
        """One of beastbt's JSON Schemas (``schemas/mission.schema.json``, ``schemas/parts/lidar.schema.json``), from
        the installed package: the editor's completion and hover always follow the schemas validation uses."""
        name = request.match_info["name"]
        parts = name.split("/")
        if (not name.endswith(".schema.json") or len(parts) > 2 or any(p in ("", ".", "..") for p in parts)
                or (len(parts) == 2 and parts[0] != "parts")):
            return WebGuard.error(404, f"no schema '{name[:80]}'")
        target = data_dir("schemas").joinpath(*parts)
        if not target.is_file():
            return WebGuard.error(404, f"no schema '{name[:80]}'")
        return web.Response(body=target.read_bytes(), content_type="application/json",
                            headers={"Cache-Control": "no-cache"})

    # -- bodies ------------------------------------------------------------------------
    async def _body(self, request: web.Request) -> dict:
        try:
            raw = await request.read()
        except web.HTTPRequestEntityTooLarge:
            raise BadRequest(413, f"the body is over {MAX_BODY_BYTES} bytes") from None
        try:
            body = json.loads(raw.decode("utf-8") if raw else "{}")
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise BadRequest(400, f"the body is not JSON: {exc}") from None
        if not isinstance(body, dict):
            raise BadRequest(400, "the body must be a JSON object")
        return body

    @staticmethod
    def _text(body: dict) -> str:
        text = body.get("text")
        if not isinstance(text, str):
            raise BadRequest(400, "give the file's text as 'text' (a string)")
        return text

    @staticmethod
    def _optional_str(body: dict, key: str) -> Optional[str]:
        value = body.get(key)
        if value is not None and not isinstance(value, str):
            raise BadRequest(400, f"'{key}' must be a string or null")
        return value or None

    # -- files ------------------------------------------------------------------------
    async def _list_files(self, request: web.Request) -> web.Response:
        files = await self._in_thread(self.folder.list)
        return web.json_response({"folder": str(self.folder.root), "files": files})

    async def _get_file(self, request: web.Request) -> web.Response:
        return web.json_response(self.folder.read(request.match_info["path"]))

    async def _put_file(self, request: web.Request) -> web.Response:
        body = await self._body(request)
        text = self._text(body)
        if "version" not in body:
            raise BadRequest(400, "give 'version': the one the file was read at, or null for a new file")
        version = self._optional_str(body, "version")
        path = request.match_info["path"]
        new = self.folder.write(path, text, version)
        return web.json_response({"path": path, "version": new})

    async def _list_robots(self, request: web.Request) -> web.Response:
        from beastbt.studio.analysis import robot_names
        return web.json_response({"robots": await self._in_thread(robot_names, self.folder)})  # walks the folder

    # -- templates ------------------------------------------------------------------------
    async def _list_templates(self, request: web.Request) -> web.Response:
        from beastbt.studio.templates import TEMPLATES
        return web.json_response({"templates": [{"name": n, "title": t.title, "description": t.description}
                                                for n, t in TEMPLATES.items()]})

    async def _template(self, request: web.Request) -> web.Response:
        from beastbt.studio.templates import TEMPLATES, template_text
        name = request.match_info["name"]
        if name not in TEMPLATES:
            from beastbt.core.errors import did_you_mean
            raise BadRequest(404, f"no template '{name[:40]}'{did_you_mean(name, TEMPLATES)}; the templates are: "
                                  f"{', '.join(TEMPLATES)}")
        body = await self._body(request)
        text = await self._in_thread(template_text, self.folder, name, body)  # it looks for the folder's worlds
        return web.json_response({"name": name, "text": text})

    # -- analysis: validate, tree, map, edit -------------------------------------------------
    async def _in_thread(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` on a daemon thread of its own (at most :data:`IO_THREADS` at once): the loop answers other
        requests meanwhile, and a thread still busy when the studio ends does not keep it alive."""
        assert self._io_slots is not None
        loop = asyncio.get_running_loop()
        done: asyncio.Future = loop.create_future()

        def settle(ok: bool, value: Any) -> None:
            if not done.done():
                done.set_result(value) if ok else done.set_exception(value)

        def run() -> None:
            try:
                result, ok = fn(*args), True
            except BaseException as exc:  # noqa: BLE001 - raised again in the request's task
                result, ok = exc, False
            try:
                loop.call_soon_threadsafe(settle, ok, result)
            except RuntimeError:  # the loop has closed: the studio ended meanwhile
                pass

        async with self._io_slots:
            threading.Thread(target=run, name="beastbt-studio-io", daemon=True).start()
            return await done

    def _json_work(self, name: str) -> Callable[[web.Request], Awaitable[web.Response]]:
        async def handle(request: web.Request) -> web.Response:
            body = await self._body(request)
            job: dict[str, Any] = {"op": name, "text": self._text(body), "path": self._optional_str(body, "path")}
            if name == "edit":
                edit = body.get("edit")
                if not isinstance(edit, dict):
                    raise BadRequest(400, "give the edit as 'edit': {op: add_place|move_place|add_fence|add_route, "
                                          "...}")
                job["edit"] = edit
            else:
                job["robot"] = self._optional_str(body, "robot")

            def gone() -> bool:
                return request.transport is None or request.transport.is_closing()

            try:
                message = await self.pool.run(job, gone)
            except WorkRefused as exc:
                return self._work_refused(name, exc)
            if "refused" in message:
                raise BadRequest(int(message.pop("refused")), str(message.pop("error")), **message)
            if "failed" in message:
                return WebGuard.error(500, f"the studio could not answer: {message['failed']}")
            return web.json_response(message["answer"])
        return handle

    def _work_refused(self, name: str, exc: WorkRefused) -> web.Response:
        """The answer to a job a worker did not finish: a too-large text is a problem at line 1 (a 413 for an
        edit), a busy studio a 503."""
        if exc.reason == "busy":
            return web.json_response({"error": "the studio is busy with other checks: try again in a moment"},
                                     status=503, headers={"Retry-After": "1"})
        if exc.reason == "closing":
            return WebGuard.error(503, "the studio is ending")
        if exc.reason == "broken":
            return WebGuard.error(500, f"the studio's workers do not start ({exc.detail}): see the studio's terminal")
        if exc.reason == "gone":
            return WebGuard.error(400, "the client went away before the answer")  # nobody reads this one
        verb, doing = WORK_VERBS[name]
        why = (f"{doing} it took more than {self.pool.timeout_s:g} s" if exc.reason == "time"
               else f"{doing} it needed more than the {self.pool.memory_bytes >> 20} MB the studio gives it")
        message = f"this text is too large to {verb} here: {why}"
        hint = ("check it with 'beastbt validate FILE' in a terminal, which has no such limit; a mission this large "
                "is better split: places in a file of their own (places: {file: ...}), repeated steps in tasks")
        if name == "edit":
            return web.json_response({"error": f"{message}; {hint}", "line": 1, "column": 1}, status=413)
        problem = {"severity": "error", "line": 1, "column": 1, "message": message, "hint": hint}
        if name == "tree":
            return web.json_response({"nodes": [], "edges": [], "root": None, "problems": [problem]})
        if name == "map":
            return web.json_response({"frame": "gps", "datum": None, "places": [], "fences": [], "routes": [],
                                      "problems": [problem]})
        return web.json_response({"problems": [problem]})

    # -- try it ------------------------------------------------------------------------
    async def _try(self, request: web.Request) -> web.Response:
        body = await self._body(request)
        text = self._text(body)
        path = self._optional_str(body, "path")
        return web.json_response(await self._in_thread(self.trials.start, text, path, body))

    async def _try_state(self, request: web.Request) -> web.Response:
        return web.json_response(self.trials.state(request.match_info["run_id"]))

    async def _try_stop(self, request: web.Request) -> web.Response:
        return web.json_response(self.trials.stop(request.match_info["run_id"]))

    async def _try_report(self, request: web.Request) -> web.StreamResponse:
        if not request.path.endswith("/"):  # the report's plots are relative to it: serve it as a folder
            raise web.HTTPFound(request.path + "/" + (f"?{request.query_string}" if request.query_string else ""))
        report = await self._in_thread(self.trials.report_file, request.match_info["run_id"])
        return web.FileResponse(report, headers={"Content-Type": "text/html", "Cache-Control": "no-store"})

    async def _try_report_asset(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info["name"]
        if name == "":
            return await self._try_report(request)
        target = await self._in_thread(self.trials.report_asset, request.match_info["run_id"], name)
        ctype = mimetypes.guess_type(target.name)[0] or "application/octet-stream"
        return web.FileResponse(target, headers={"Content-Type": ctype, "Cache-Control": "no-store"})

    async def _try_console(self, request: web.Request) -> web.Response:
        body = await request.read() if request.method == "POST" else None
        status, answer = await self.trials.console(request.match_info["run_id"], request.method,
                                                   request.match_info["what"], body)
        return web.json_response(answer, status=status)

    # -- mission tests ------------------------------------------------------------------------
    def _mission_path(self, request: web.Request, body: Optional[dict] = None) -> str:
        path = (body or {}).get("path") if body is not None else request.query.get("path")
        if not isinstance(path, str) or not path:
            raise BadRequest(400, "give the mission's 'path' (its file in the folder)")
        return path

    async def _list_tests(self, request: web.Request) -> web.Response:
        from beastbt.studio.mission_tests import tests_of
        path = self._mission_path(request)
        return web.json_response({"path": path, "tests": await self._in_thread(tests_of, self.folder, path)})

    async def _new_test(self, request: web.Request) -> web.Response:
        from beastbt.studio.mission_tests import TestExists, new_test
        body = await self._body(request)
        try:
            return web.json_response(await self._in_thread(new_test, self.folder, self._mission_path(request, body)))
        except TestExists as exc:
            raise BadRequest(409, str(exc), path=exc.path) from None

    async def _test(self, request: web.Request) -> web.Response:
        body = await self._body(request)
        return web.json_response(await self._in_thread(self.tests.start, self._mission_path(request, body)))

    async def _test_state(self, request: web.Request) -> web.Response:
        return web.json_response(await self._in_thread(self.tests.state, request.match_info["test_id"]))

    async def _test_stop(self, request: web.Request) -> web.Response:
        return web.json_response(await self._in_thread(self.tests.stop, request.match_info["test_id"]))

    async def _no_api(self, request: web.Request) -> web.Response:
        return WebGuard.error(404 if request.method in ("GET", "POST", "PUT") else 405,
                              f"no API {request.method} {request.path[:80]}: see docs/studio.md")


__all__ = ["DEFAULT_PORT", "StudioServer"]
