"""The station: a Zenoh router for the fleet, the table of its robots, and the HTTP API people and pages use.

:class:`Station` is this process on the fleet: a Zenoh *router* (robots
connect to it) with the station's liveliness token (what a supervised mission
waits for), and a :class:`FleetTable` kept from the robots' liveliness tokens,
states and events. :class:`StationServer` serves the HTTP API on it, with the
operator console's server underneath (:class:`~beastbt.live.console_server.ConsoleServer`):
the same guard (Host, Origin, JSON-only controls, the token off loopback), the
same security headers and the same JSON errors.

The API (docs/fleet.md):

* ``GET /api/robots``: ``{"robots": [{name, status, alive, pose, battery, step, progress, last_seen_s, ...}]}``,
  those that need attention first (a question, a failure or an e-stop, lost); a robot whose
  liveliness token went (or whose state stopped for :data:`LOST_AFTER_S`) is ``alive: false``, ``status: lost``;
  its ``console_url`` only when ``http(s)://`` on the robot's own address (else null, and ``console_url_problem``
  says why: :mod:`~beastbt.fleet.console_link`);
* ``GET /api/robots/<name>/photo.jpg``: the robot's newest photo (a JPEG of at most 100 kB,
  :mod:`~beastbt.fleet.photos`); its ``photo`` in the list: ``{name, time_s, bytes, url}`` or null;
* ``POST /api/robots/<name>/<control>``: the robot's answer (its queryable ``beastbt/<name>/cmd/<control>``);
* ``POST /api/robots/<name>/mission``: a mission (YAML, ``{"mission": YAML}`` or a zip with its files) to a
  ``beastbt serve`` robot: ``started``, or the validation errors as ``beastbt validate`` prints them;
* ``POST /api/estop-all``: a put on ``beastbt/fleet/estop``; never refused (any body, any content type).
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

from aiohttp import web

from beastbt.fleet import keys
from beastbt.fleet.agent import MISSION_MAX_BYTES
from beastbt.fleet.config import station_config
from beastbt.fleet.console_link import link_addresses, robot_console_url
from beastbt.fleet.shared_world import RELAY_PERIOD_S, check_sim_field, poses_payload
from beastbt.sim.obstacles import OTHERS_MAX_AGE_S
from beastbt.live.console_control import CONTROL_MAX_BYTES, Refused, parse_control_body
from beastbt.live.console_server import ConsoleServer

LOST_AFTER_S = 2.0
"""A robot whose state has not come for this long (wall s) is lost even while its token stands (a link cut
that the transport has not noticed yet)."""
COMMAND_TIMEOUT_S = 3.0
"""How long the station waits for a robot's answer to a control (s): its own wait for a tick is 2 s."""
MISSION_TIMEOUT_S = 30.0
"""How long the station waits for a robot to check a mission and start it (s): it loads the world and the parts."""
EVENTS_KEPT = 50
"""The newest events kept per robot."""
ALERTS_KEPT = 5
"""The newest alerts (events of kind ``alert``, a mission's ``alert`` step) listed per robot, kept apart from the
events so that a busy run's other events do not push them out."""
MISSION_TYPES = ("application/json", "application/yaml", "application/x-yaml", "text/yaml", "text/x-yaml",
                 "application/zip")
"""What a mission may be sent as without the token: none of them is a form's or ``text/plain`` (a page on
another site must ask first, and is told no)."""
STATION_FILES = {"station.js": "application/javascript", "station.css": "text/css"}
"""The station page's own files (``station_page/``); the rest (stylesheet, icon) is the console's."""
ATTENTION = {"question": 0, "failed": 1, "aborted": 1, "estop": 1, "lost": 2}
"""What needs a person first (lower first): an open question, then a failure or e-stop, then a robot lost."""


@dataclass
class RobotEntry:
    """What the station knows of one robot: its token, its last state (wall time it came) and its events."""

    name: str
    alive: bool = False
    state: dict = field(default_factory=dict)
    seen_wall: Optional[float] = None
    events: deque = field(default_factory=lambda: deque(maxlen=EVENTS_KEPT))
    alerts: deque = field(default_factory=lambda: deque(maxlen=ALERTS_KEPT))
    photo: Optional[tuple[str, float, bytes, int]] = None
    """The robot's newest photo: (its name, its run's time s, the JPEG, a number that changes with each one)."""


class FleetTable:
    """The robots the station has heard of, updated from Zenoh's threads; ``wall`` is a monotonic clock (s);
    ``addresses`` says where each Zenoh session connected now comes from (Zenoh id -> address), what a robot's
    ``console_url`` is checked against (:mod:`~beastbt.fleet.console_link`)."""

    def __init__(self, wall: Callable[[], float] = time.monotonic,
                 addresses: Callable[[], dict[str, str]] = dict) -> None:
        self.wall = wall
        self.addresses = addresses
        self._lock = threading.Lock()
        self._robots: dict[str, RobotEntry] = {}

    def _entry(self, name: str) -> RobotEntry:
        entry = self._robots.get(name)
        if entry is None:
            entry = self._robots[name] = RobotEntry(name)
        return entry

    def alive(self, name: str, present: bool) -> None:
        """A robot's token appeared (True) or went (False)."""
        with self._lock:
            self._entry(name).alive = present

    def state(self, name: str, state: dict) -> None:
        """A robot's state came."""
        with self._lock:
            entry = self._entry(name)
            entry.state = state
            entry.seen_wall = self.wall()

    def event(self, name: str, event: dict) -> None:
        """A robot's event came."""
        with self._lock:
            entry = self._entry(name)
            entry.events.append(event)
            if event.get("kind") == "alert":
                entry.alerts.append(event)

    def photo(self, name: str, photo_name: str, time_s: float, jpeg: bytes) -> None:
        """A robot's newest photo came (a JPEG): it replaces the one before."""
        with self._lock:
            entry = self._entry(name)
            seq = entry.photo[3] + 1 if entry.photo is not None else 1
            entry.photo = (photo_name, time_s, bytes(jpeg), seq)

    def photo_jpeg(self, name: str) -> Optional[bytes]:
        """The robot's newest photo's JPEG, or None."""
        with self._lock:
            entry = self._robots.get(name)
            return entry.photo[2] if entry is not None and entry.photo is not None else None

    def is_alive(self, entry: RobotEntry, now: float) -> bool:
        """The robot's token stands and its state is fresh."""
        return entry.alive and entry.seen_wall is not None and now - entry.seen_wall <= LOST_AFTER_S

    def robots(self) -> list[dict]:
        """Every robot as ``GET /api/robots`` lists it, those that need attention first, then by name."""
        now = self.wall()
        with self._lock:
            entries = list(self._robots.values())
        out = []
        addresses = self.addresses() if any(e.state.get("console_url") for e in entries) else {}
        for e in entries:
            s = e.state
            alive = self.is_alive(e, now)
            zid = s.get("zid")
            address = addresses.get(zid) if isinstance(zid, str) else None
            console_url, console_problem = robot_console_url(s.get("console_url"), address)
            status = s.get("status", "idle") if alive else "lost"
            item = {"name": e.name, "status": status, "alive": alive, "pose": s.get("pose"), "gps": s.get("gps"),
                    "battery": s.get("battery"), "step": s.get("step"), "progress": s.get("progress"),
                    "last_seen_s": None if e.seen_wall is None else round(now - e.seen_wall, 2),
                    "mission": s.get("mission"), "question": s.get("question"), "estop": bool(s.get("estop")),
                    "last_run": s.get("last_run"), "console_url": console_url,
                    "console_url_problem": console_problem, "events": list(e.events)[-5:],
                    "alerts": list(e.alerts),
                    "photo": None if e.photo is None else {
                        "name": e.photo[0], "time_s": e.photo[1], "bytes": len(e.photo[2]),
                        "url": f"/api/robots/{e.name}/photo.jpg?n={e.photo[3]}"}}
            item["attention"] = self.attention(item)
            out.append(item)
        out.sort(key=lambda r: (r["attention"] if r["attention"] is not None else 9, r["name"]))
        return out

    @staticmethod
    def attention(robot: dict) -> Optional[int]:
        """How urgently a person is needed (lower first), or None: see :data:`ATTENTION`."""
        if robot["alive"] and robot.get("question"):
            return ATTENTION["question"]
        if robot["estop"] and robot["alive"]:
            return ATTENTION["estop"]
        return ATTENTION.get(robot["status"])

    def sim_poses(self) -> list[tuple[str, dict, float]]:
        """The simulated robots heard within :data:`~beastbt.sim.obstacles.OTHERS_MAX_AGE_S`: (name, their ``sim``
        field, how long ago, s), by name; what the station relays on ``beastbt/fleet/sim/poses``."""
        now = self.wall()
        with self._lock:
            entries = [(e.name, e.state.get("sim"), e.seen_wall) for e in self._robots.values()]
        out = []
        for name, value, seen in sorted(entries, key=lambda e: e[0]):
            sim = check_sim_field(value)
            if sim is not None and seen is not None and now - seen <= OTHERS_MAX_AGE_S:
                out.append((name, sim, now - seen))
        return out

    def known_alive(self, name: str) -> bool:
        """Whether ``name`` is on the fleet now."""
        with self._lock:
            entry = self._robots.get(name)
        return entry is not None and self.is_alive(entry, self.wall())


class Station:
    """This process on the fleet: a Zenoh router listening on ``listen``, the station's token and the table."""

    def __init__(self, listen: Optional[str], config_file: Optional[str] = None) -> None:
        self.listen = listen
        self.config_file = config_file
        self.table = FleetTable(addresses=self.addresses)
        self._session: Any = None
        self._declared: list[Any] = []
        self._relay_stop = threading.Event()
        self._relay: Optional[threading.Thread] = None
        self.relayed = 0
        """Puts on ``beastbt/fleet/sim/poses`` so far."""

    def open(self) -> "Station":
        """Open the router (raises zenoh's error when it cannot listen) and start hearing the robots."""
        import zenoh
        session = zenoh.open(station_config(self.listen, self.config_file))
        self._session = session
        live = session.liveliness()
        self._declared = [
            live.declare_subscriber(keys.ALL_ALIVE, self._on_alive, history=True),
            session.declare_subscriber(keys.ALL_STATES, self._on_state),
            session.declare_subscriber(keys.ALL_EVENTS, self._on_event),
            session.declare_subscriber(keys.ALL_PHOTOS, self._on_photo),
            live.declare_token(keys.STATION_ALIVE),
        ]
        poses = session.declare_publisher(keys.SIM_POSES)
        self._declared.append(poses)
        self._relay = threading.Thread(target=self._relay_poses, args=(poses,), name="beastbt-station-sim-poses",
                                       daemon=True)
        self._relay.start()
        return self

    def addresses(self) -> dict[str, str]:
        """Where each session linked to the router now comes from: Zenoh id -> address (none when closed)."""
        session = self._session
        if session is None:
            return {}
        try:
            return link_addresses(session.info.links())
        except Exception:  # noqa: BLE001 - closing: no address is known
            return {}

    def _relay_poses(self, publisher: Any) -> None:
        """Put the simulated robots' poses every :data:`RELAY_PERIOD_S` while there are any (a thread of its own):
        robots do not hear each other, the station hears them all (see :mod:`beastbt.fleet.shared_world`)."""
        due = time.monotonic()
        while True:
            due += RELAY_PERIOD_S
            if self._relay_stop.wait(max(0.0, due - time.monotonic())):
                return
            robots = self.table.sim_poses()
            if len(robots) < 2:
                continue  # one simulated robot has no other to meet
            try:
                publisher.put(poses_payload(robots))
                self.relayed += 1
            except Exception:  # noqa: BLE001 - the router is closing: nothing more to relay
                return

    def close(self) -> None:
        """Withdraw the station's token and close the router."""
        session, self._session = self._session, None
        if session is None:
            return
        self._relay_stop.set()
        if self._relay is not None:
            self._relay.join(2.0)
        for entity in reversed(self._declared):
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 - closing whatever happened
                pass
        session.close()

    # -- hearing the robots (Zenoh's threads) ------------------------------------------------
    def _on_alive(self, sample: Any) -> None:
        import zenoh
        name = keys.robot_of(str(sample.key_expr))
        if name is not None:
            self.table.alive(name, sample.kind == zenoh.SampleKind.PUT)

    def _on_state(self, sample: Any) -> None:
        name = keys.robot_of(str(sample.key_expr))
        state = _json_object(sample.payload.to_bytes())
        if name is not None and state is not None:
            self.table.state(name, state)

    def _on_event(self, sample: Any) -> None:
        name = keys.robot_of(str(sample.key_expr))
        event = _json_object(sample.payload.to_bytes())
        if name is not None and event is not None:
            self.table.event(name, event)

    def _on_photo(self, sample: Any) -> None:
        from beastbt.fleet.photos import PHOTO_MAX_BYTES, read_attachment
        name = keys.robot_of(str(sample.key_expr))
        jpeg = sample.payload.to_bytes()
        # a JPEG of the size robots send, or nothing: the page shows it as it came
        if name is not None and jpeg[:2] == b"\xff\xd8" and len(jpeg) <= 2 * PHOTO_MAX_BYTES:
            meta = read_attachment(sample)
            self.table.photo(name, meta["name"], meta["time_s"], jpeg)

    # -- asking them (any thread; blocks up to the timeout) ---------------------------------------
    def ask(self, key: str, payload: bytes, timeout_s: float) -> Optional[tuple[bool, dict]]:
        """Query ``key`` with ``payload``: (ok, the answer's JSON object), or None when nobody answered."""
        session = self._session
        if session is None:
            return None
        for reply in session.get(key, payload=payload, timeout=timeout_s):
            if reply.ok is not None:
                return True, _json_object(reply.ok.payload.to_bytes()) or {}
            return False, _json_object(reply.err.payload.to_bytes()) or {"error": "the robot's answer is not JSON"}
        return None

    def estop_all(self) -> None:
        """Put on ``beastbt/fleet/estop``: every robot that hears it latches its e-stop."""
        session = self._session
        if session is not None:
            session.put(keys.ESTOP_ALL, json.dumps({"by": "station"}))


def _station_file(name: str) -> bytes:
    from importlib import resources
    return resources.files("beastbt.fleet").joinpath("station_page", name).read_bytes()


def _json_object(raw: bytes) -> Optional[dict]:
    try:
        value = json.loads(bytes(raw))
    except (ValueError, UnicodeDecodeError, RecursionError):
        return None
    return value if isinstance(value, dict) else None


class StationServer(ConsoleServer):
    """The station's HTTP API (module docstring) on ``host:port``, guarded as the console is."""

    def __init__(self, station: Station, host: str = "127.0.0.1", port: int = 0, token: Optional[str] = None,
                 require_token: Optional[bool] = None) -> None:
        super().__init__(None, None, None, dict, host, port, token, require_token)  # no run: no state, video, map
        self.station = station
        self._waiters = ThreadPoolExecutor(max_workers=8, thread_name_prefix="beastbt-station-wait")
        """Threads that wait for the robots' answers (a query over Zenoh blocks), off the event loop."""

    def close(self, timeout_s: float = 3.0) -> None:
        """Stop serving (as the console's server does) and the threads that wait for answers."""
        super().close(timeout_s)
        self._waiters.shutdown(wait=False, cancel_futures=True)

    def body_types(self, request: web.Request) -> tuple[str, ...]:
        """JSON for the controls; a mission may also be YAML or a zip (see :data:`MISSION_TYPES`); the stop-all
        takes anything: stopping every robot is never refused for the way it was asked."""
        if request.path == "/api/estop-all":
            return (request.content_type,)
        if request.path.endswith("/mission"):
            if "Content-Type" not in request.headers:
                return (request.content_type,)  # no type at all (curl -H 'Content-Type:'): the body says what it is
            return MISSION_TYPES
        return super().body_types(request)

    def _refusal(self, request: web.Request) -> Optional[web.Response]:
        """The console's guard; a mission refused for its type is told the types a mission may have (not JSON's)."""
        refusal = super()._refusal(request)
        if (refusal is not None and request.method == "POST" and request.path.endswith("/mission")
                and request.content_type not in self.body_types(request) and b"needs Content-Type" in refusal.body):
            return self.guard.error(403, f"a mission is sent as application/yaml, application/zip, application/json "
                                         f"({{\"mission\": YAML}}) or with no Content-Type, not as "
                                         f"'{request.content_type[:60]}' (a form's type, which a page on another "
                                         f"site could send): e.g. curl --data-binary @mission.yaml -H "
                                         f"'Content-Type: application/yaml' ...")
        return refusal

    async def _bind(self) -> None:
        app = web.Application(middlewares=[self._guard], client_max_size=MISSION_MAX_BYTES)
        app.on_response_prepare.append(self._headers)
        app.router.add_get("/", self._page)
        app.router.add_get("/static/{name}", self._station_static)
        app.router.add_get("/favicon.ico", self._favicon)
        app.router.add_get("/api/robots", self._robots)
        app.router.add_get("/api/robots/{name}/photo.jpg", self._photo)
        app.router.add_post("/api/estop-all", self._estop_all)
        app.router.add_post("/api/robots/{name}/mission", self._mission)
        app.router.add_post("/api/robots/{name}/{control}", self._control)
        self._ending = asyncio.Event()
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.requested_port, reuse_address=True)
        await site.start()
        sockets = getattr(site._server, "sockets", None) or []  # the bound port when 0 was asked for
        if sockets:
            self.port = sockets[0].getsockname()[1]

    async def _page(self, request: web.Request) -> web.Response:
        return web.Response(body=_station_file("index.html"), content_type="text/html", charset="utf-8",
                            headers={"Cache-Control": "no-cache"})

    async def _station_static(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name in STATION_FILES:
            return web.Response(body=_station_file(name), content_type=STATION_FILES[name],
                                headers={"Cache-Control": "no-cache"})
        return await self._static(request)  # the console's own stylesheet and icon

    async def _robots(self, request: web.Request) -> web.Response:
        return web.json_response({"robots": self.station.table.robots()})

    async def _photo(self, request: web.Request) -> web.Response:
        name = self._robot(request)
        jpeg = self.station.table.photo_jpeg(name)
        if jpeg is None:
            return web.json_response({"error": f"no photo from robot '{name}' yet"}, status=404)
        return web.Response(body=jpeg, content_type="image/jpeg")

    async def _estop_all(self, request: web.Request) -> web.Response:
        self.station.estop_all()
        names = [r["name"] for r in self.station.table.robots() if r["alive"]]
        return web.json_response({"ok": True, "estop": True, "robots": names})

    def _robot(self, request: web.Request) -> str:
        name = request.match_info["name"]
        problem = keys.name_problem(name)
        if problem is not None:
            raise Refused(400, problem)
        return name

    async def _control(self, request: web.Request) -> web.Response:
        name = self._robot(request)
        control = request.match_info["control"]
        if control not in keys.CONTROLS:
            return web.json_response({"error": f"no control '{control[:40]}': the controls are "
                                               f"{', '.join(keys.CONTROLS)} (and mission)"}, status=404)
        raw = await request.read()
        if len(raw) > CONTROL_MAX_BYTES:
            raise Refused(413, f"the body has {len(raw)} bytes: a control is a small JSON object")
        if control != "estop":  # the e-stop is never refused for its body
            parse_control_body(raw)  # refused here, with the reason, before it goes on the fleet
        return await self._ask(name, keys.cmd_key(name, control), raw if control != "estop" else b"{}",
                               COMMAND_TIMEOUT_S)

    async def _mission(self, request: web.Request) -> web.Response:
        name = self._robot(request)
        raw = await request.read()
        if request.content_type == "application/json":
            body = _json_object(raw)
            if body is None or not isinstance(body.get("mission"), str):
                raise Refused(400, "expected {\"mission\": \"<the mission's YAML>\"}, or the YAML itself "
                                   "(Content-Type: application/yaml), or a zip with its files (application/zip)")
            raw = body["mission"].encode("utf-8")
        elif "Content-Type" not in request.headers:
            # no type at all: the body says what it is (a zip's signature, {"mission": ...}, else the YAML)
            body = _json_object(raw) if raw.lstrip()[:1] == b"{" else None
            if body is not None and isinstance(body.get("mission"), str):
                raw = body["mission"].encode("utf-8")
        return await self._ask(name, keys.mission_key(name), raw, MISSION_TIMEOUT_S)

    async def _ask(self, name: str, key: str, payload: bytes, timeout_s: float) -> web.Response:
        loop = asyncio.get_running_loop()
        answer = await loop.run_in_executor(self._waiters, self.station.ask, key, payload, timeout_s)
        if answer is None:
            if self.station.table.known_alive(name):
                return web.json_response({"error": f"robot '{name}' did not answer within {timeout_s:g} s"},
                                         status=504)
            return web.json_response({"error": f"no robot '{name}' on the fleet (or it is lost)"}, status=404)
        ok, body = answer
        if ok:
            return web.json_response({**body, "ok": True})
        status = body.get("status")
        status = status if isinstance(status, int) and 400 <= status < 600 else 502
        return web.json_response({k: v for k, v in body.items() if k not in ("ok", "status")}, status=status)


def _json_object(raw: bytes) -> Optional[dict]:
    """``raw`` as a JSON object, or None when it is not one."""
    try:
        body = json.loads(raw) if raw.strip() else None
    except (ValueError, RecursionError):
        return None
    return body if isinstance(body, dict) else None


__all__ = ["Station", "StationServer", "FleetTable", "RobotEntry", "LOST_AFTER_S"]
