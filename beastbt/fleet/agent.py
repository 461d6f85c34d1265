"""The robot's side of the fleet: its Zenoh session, liveliness token, state, events, photos and command queryables.

A :class:`FleetAgent` lives as long as the robot is on the fleet: the length
of one ``beastbt run --fleet``, or of ``beastbt serve``, across its missions.
All of it is I/O on Zenoh's threads and one publisher thread of its own; the
run (when one is attached, :class:`~beastbt.fleet.run_link.FleetRunLink`) is
only ever touched the way the operator console touches it: controls go
through :class:`~beastbt.live.console_control.ConsoleControls` (carried out on
the tick thread) and the e-stop through
:func:`~beastbt.run.safety.request_estop` (safe from any thread).

The session is opened in the publisher thread, so that a robot whose station
is not up (yet, or any more) starts and runs all the same: Zenoh connects in
the background and reconnects by itself, declaring again what was declared.

What it answers (``beastbt/<name>/cmd/<control>``, see :mod:`~beastbt.fleet.keys`):
a JSON object ``{"ok": true, ...}`` (the console's answer), or an error reply
``{"ok": false, "status": 409|400|503, "error": "..."}``. The e-stop (and the
fleet-wide ``beastbt/fleet/estop``) is never refused: with no mission running
it latches the robot's own e-stop, and no mission starts until ``estop_reset``.
"""

from __future__ import annotations

import json
import queue
import sys
import threading
import time
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass
from typing import Any, Callable, Optional

from beastbt.core.file_refs import MISSION
from beastbt.fleet import keys
from beastbt.fleet.config import FleetOptions, robot_config
from beastbt.fleet.shared_world import others_of, sim_field
from beastbt.sim.obstacles import OtherRobots

PUBLISH_PERIOD_S = 0.175
"""The state is published this often (wall s): 5.7 times a second, in the contract's 5-10 Hz with a margin, and a
state of 6 kB (a tree, a LiDAR scan on the map) stays near 35 kB/s, under the 50 kB/s a robot may use."""
EARLY_EVENTS = 200
"""Events of the run kept while the session is still opening (the set-up's), published once it is open."""
CONTROL_TIMEOUT_S = 2.0
"""How long a control waits for the tick thread before the answer is 503 (s), as the console's."""
MISSION_MAX_BYTES = 4 << 20
"""The largest mission a robot takes (bytes): a YAML file, or a zip with the files it names."""


@dataclass
class MissionRequest:
    """A mission that came on ``beastbt/<name>/mission``: its bytes, and how to answer (once)."""

    payload: bytes
    answer: Callable[[bool, dict], None]
    on_robot: bool = False
    """Made on the robot itself from its own profile (a ROS 2 goal with the profile's ``ros2: map:``), not sent
    over the network: the files it names are read as written, as on the command line."""


class FleetAgent:
    """One robot on the fleet (see the module docstring); ``name`` must be a valid robot name.

    ``takes_missions``: a mission on ``beastbt/<name>/mission`` goes to :attr:`missions` (``beastbt serve``);
    else it is refused (a ``beastbt run`` runs its one mission). ``wall`` is a monotonic clock (s).
    """

    def __init__(self, name: str, options: FleetOptions, takes_missions: bool = False,
                 wall: Callable[[], float] = time.monotonic) -> None:
        self.name = keys.check_name(name)
        self.options = options
        self.config = robot_config(options)
        """The Zenoh configuration, made now: a bad ``--fleet-config`` is said before anything moves."""
        self.takes_missions = takes_missions
        self.wall = wall
        self.missions: "queue.Queue[MissionRequest]" = queue.Queue()
        """Missions waiting for the serving loop (at most one: another is refused while one waits or runs)."""
        self.link: Any = None
        """The run now reporting through this agent (a :class:`~beastbt.fleet.run_link.FleetRunLink`), or None."""
        self.estop_latched = False
        """The e-stop came while no mission ran: no mission starts until ``estop_reset``."""
        self.station_present = False
        """The station's liveliness token is seen now (written by Zenoh's thread, read by the run's failsafe)."""
        self.last_run: Optional[dict] = None
        """``{mission, status}`` of the last run that ended (status as in the summary: success, failure, stopped)."""
        self.last_state: dict = {}
        self.sim: Any = None
        """The simulator of the run now reporting through this agent (None on a robot, or with no run)."""
        self.sim_pose: Optional[dict] = None
        """The ``sim`` field (:func:`~beastbt.fleet.shared_world.sim_field`) of a simulated robot standing idle:
        where its last run left it, or where it starts (None on a real robot)."""
        self.standing: Optional[dict] = None
        """A simulated robot before its first run: ``{x, y, yaw, battery_v}`` (m, rad in its world's frame; V), where
        it stands and its battery, for its idle state (None on a robot: nothing reads its devices while it waits)."""
        self.zid: Optional[str] = None
        """The Zenoh id of the robot's session once open: in its state, so that the station finds the address it
        connects from (what the robot's ``console_url`` must be on)."""
        self.others = OtherRobots(wall)
        """The other simulated robots of this robot's world, as the station relays them (``keys.SIM_POSES``)."""
        self.published = 0
        self._pending_mission = False
        self._lock = threading.Lock()
        self._session: Any = None
        self._declared: list[Any] = []
        self._state_pub: Any = None
        self._events_pub: Any = None
        self._photo_pub: Any = None
        self._photo_due: Optional[tuple[str, float, str]] = None
        """The newest photo not yet put on the fleet: (name, time_s, path); the publisher thread sends it."""
        self.photos_sent = 0
        self._early: list[tuple[float, str, str]] = []
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.open_error: Optional[str] = None

    # -- life ------------------------------------------------------------------------------
    def start(self) -> "FleetAgent":
        """Open the session and start publishing, in a thread of its own (returns at once)."""
        self._thread = threading.Thread(target=self._serve, name=f"beastbt-fleet-{self.name}", daemon=True)
        self._thread.start()
        return self

    def wait_open(self, timeout_s: float) -> bool:
        """Wait until the session is open (s); False when it is not by then."""
        end = time.monotonic() + timeout_s
        while self._session is None and self.open_error is None and time.monotonic() < end:
            time.sleep(0.01)
        return self._session is not None

    def close(self) -> None:
        """Publish the last state, withdraw the liveliness token and close the session."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)

    def _serve(self) -> None:
        import zenoh
        try:
            session = zenoh.open(self.config)
        except Exception as exc:  # noqa: BLE001 - the run goes on without the fleet, and says so
            self.open_error = str(exc)[:300]
            print(f"beastbt: fleet: the robot is not on the fleet (the run goes on): {self.open_error}",
                  file=sys.stderr, flush=True)
            return
        try:
            self.zid = str(session.zid())
            events_pub = self._declare(session)
            with self._lock:  # the set-up's events first, then each as it happens
                early, self._early = self._early, []
                self._session = session
            for event in early:
                self._put_event(events_pub, *event)
            self._events_pub = events_pub
            due = time.monotonic()
            while True:  # on a fixed schedule: the rate does not drift below the period by the time a put takes
                due += PUBLISH_PERIOD_S
                if self._stop.wait(max(0.0, due - time.monotonic())):
                    break
                self.publish_state()
                self._publish_photo()
            self.publish_state()
            self._publish_photo()
        finally:
            self._session = None
            for entity in reversed(self._declared):
                try:
                    entity.undeclare()
                except Exception:  # noqa: BLE001 - closing whatever happened
                    pass
            session.close()

    def _declare(self, session: Any) -> Any:
        """Declare the robot's keys on ``session``; return the events' publisher (set once early events went)."""
        name = self.name
        self._state_pub = session.declare_publisher(keys.state_key(name))
        events_pub = session.declare_publisher(keys.events_key(name))
        self._photo_pub = session.declare_publisher(keys.photo_key(name))
        declared = [self._state_pub, events_pub, self._photo_pub]
        for control in keys.CONTROLS:
            declared.append(session.declare_queryable(keys.cmd_key(name, control),
                                                      lambda query, c=control: self._on_control(c, query)))
        declared.append(session.declare_queryable(keys.mission_key(name), self._on_mission))
        declared.append(session.declare_subscriber(keys.ESTOP_ALL, self._on_estop_all))
        declared.append(session.declare_subscriber(keys.SIM_POSES, self._on_sim_poses))
        declared.append(session.liveliness().declare_subscriber(keys.STATION_ALIVE, self._on_station, history=True))
        declared.append(session.liveliness().declare_token(keys.alive_key(name)))
        self._declared = declared
        return events_pub

    # -- what it publishes --------------------------------------------------------------------
    def idle_state(self) -> dict:
        """The state of a robot with no mission running: the console's fields, most of them empty, with its pose and
        battery: a robot's last estimate and battery (from its last run); a simulated robot's pose where it stands
        (its true pose in a shared world; else its last run's estimate, or its world's start before any run) and its
        last run's battery (before any run, its world's start battery)."""
        last, standing = self.last_state, self.standing
        pose = last.get("pose")
        if self.sim_pose is not None:
            pose = _console_pose(self.sim_pose)
        elif pose is None and standing is not None:
            pose = _console_pose(standing)
        battery = last.get("battery")
        if battery is None and standing is not None and standing.get("battery_v") is not None:
            from beastbt.live.console_state import battery_percent
            volts = float(standing["battery_v"])
            battery = {"volts": round(volts, 2), "percent": round(battery_percent(volts), 0)}
        return {"mission": None, "status": "idle", "time_s": 0.0, "step": None, "last_step": None, "progress": None,
                "pose": pose, "gps": last.get("gps"), "speed_mps": 0.0, "battery": battery,
                "estop": self.estop_latched, "teleop": False, "question": None, "tree": [], "ended_at": None,
                "events": [], "command": {"linear_mps": 0.0, "angular_rps": 0.0}, "paused_by": None}

    def current_state(self) -> dict:
        """What goes on ``beastbt/<name>/state`` now: the run's last state (or the idle one), its ``robot`` and
        ``last_run``, and whether the station is seen."""
        link = self.link
        state = dict(link.latest() if link is not None else self.idle_state())
        state["robot"] = self.name
        console = link.run.ctx.services.plugins.get("console") if link is not None else None
        # where the run's own console is (tree, video, joystick), without its token: the fleet is not the console
        state["console_url"] = console.url.split("?")[0] if console is not None and console.url else None
        state["last_run"] = self.last_run
        state["station"] = self.station_present
        state["zid"] = self.zid
        sim = self.sim
        pose = sim_field(sim) if sim is not None else self.sim_pose
        if pose is not None:  # only a simulated robot: its true pose, for the other simulators of its world
            state["sim"] = pose
        return state

    # -- a shared simulated world -------------------------------------------------------------
    def attach_sim(self, sim: Any) -> None:
        """A simulated run reports through this agent: its true pose goes in the state, and its simulator takes
        the other robots of its world from :attr:`others`, between ticks."""
        self.sim_pose = sim_field(sim)
        self.sim = sim
        sim.others = self.others.take

    def detach_sim(self) -> None:
        """The simulated run has ended: the robot stands where it stopped, still an obstacle to the others."""
        sim, self.sim = self.sim, None
        if sim is not None:
            self.sim_pose = sim_field(sim)
            sim.others = None

    def stand(self, pose: dict, battery_v: Optional[float] = None, shared: bool = True) -> None:
        """A simulated robot stands idle at ``pose`` (a ``sim`` field) with ``battery_v`` (V) before its first run;
        ``shared``: in a world shared with the fleet's other simulated robots (it is an obstacle to them)."""
        if shared:
            self.sim_pose = dict(pose)
        self.standing = {"x": pose["x"], "y": pose["y"], "yaw": pose["yaw"], "battery_v": battery_v}

    def _on_sim_poses(self, sample: Any) -> None:
        pose = self.sim_pose
        self.others.put(others_of(sample.payload.to_bytes(), self.name, pose["world"] if pose else None))

    def publish_state(self) -> None:
        """Put the current state (the publisher thread)."""
        pub = self._state_pub
        if pub is None:
            return
        try:
            pub.put(json.dumps(self.current_state(), separators=(",", ":")))
            self.published += 1
        except Exception:  # noqa: BLE001 - a closed session at the end: nothing more to say
            pass

    def publish_event(self, time_s: float, kind: str, text: str) -> None:
        """Put one event (any thread; Zenoh drops rather than blocks when the link is congested)."""
        pub = self._events_pub
        if pub is None:
            with self._lock:
                if self._session is None and self.open_error is None and len(self._early) < EARLY_EVENTS:
                    self._early.append((time_s, kind, text))
            return
        self._put_event(pub, time_s, kind, text)

    def photo_taken(self, name: str, time_s: float, path: str) -> None:
        """A run saved a photo (any thread, the tick thread's included: this only notes it): the publisher thread
        puts it on ``beastbt/<name>/photo``, made small (:func:`~beastbt.fleet.photos.fleet_jpeg`). A photo not yet
        sent when a newer one comes is skipped: the station shows the newest."""
        self._photo_due = (name, float(time_s), str(path))

    def _publish_photo(self) -> None:
        """Put the newest photo not yet sent (the publisher thread: reading and encoding it stay off the tick)."""
        due, pub = self._photo_due, self._photo_pub
        if due is None or pub is None:
            return
        self._photo_due = None
        from beastbt.fleet.photos import fleet_jpeg, photo_attachment
        try:
            jpeg = fleet_jpeg(due[2])
            if jpeg is not None:
                pub.put(jpeg, attachment=photo_attachment(self.name, due[0], due[1]))
                self.photos_sent += 1
        except Exception:  # noqa: BLE001 - the run never fails for the fleet link (a photo gone, a closed session)
            pass

    def _put_event(self, pub: Any, time_s: float, kind: str, text: str) -> None:
        try:
            pub.put(json.dumps({"robot": self.name, "time_s": round(time_s, 2), "kind": kind, "text": text}))
        except Exception:  # noqa: BLE001 - the run never fails for the fleet link
            pass

    # -- runs ---------------------------------------------------------------------------------
    def attach(self, link: Any) -> None:
        """A run reports through this agent from now on."""
        with self._lock:
            self.link = link
            self._pending_mission = False

    def detach(self, last_run: Optional[dict]) -> None:
        """The run has ended (``last_run``: its mission and summary status): the robot is idle again."""
        with self._lock:
            if self.link is not None:
                self.last_state = self.link.latest()
            self.link = None
            self.last_run = last_run
            self.detach_sim()
        self.publish_state()

    def mission_done(self) -> None:
        """The serving loop is done with a mission request (refused or run): the next one may come."""
        with self._lock:
            self._pending_mission = False

    # -- what it answers ----------------------------------------------------------------------
    def _on_station(self, sample: Any) -> None:
        import zenoh
        self.station_present = sample.kind == zenoh.SampleKind.PUT

    def _on_estop_all(self, sample: Any) -> None:
        self.estop("the fleet's stop-all")

    def estop(self, reason: str) -> dict:
        """Latch the e-stop: the run's (mux and watchdog, any thread), or the idle robot's own. Never refused."""
        from beastbt.run.safety import request_estop
        link = self.link
        self.estop_latched = True
        if link is not None and link.run.status is None:
            first = request_estop(link.run, reason)
            link.run.io.wakeup.set()
            return {"estop": True, "newly_latched": first, "running": True}
        return {"estop": True, "running": False}

    def _on_control(self, control: str, query: Any) -> None:
        try:
            ok, body = self.control(control, _payload(query))
        except Exception as exc:  # noqa: BLE001 - never a traceback on Zenoh's thread, always an answer
            ok, body = False, {"status": 500, "error": f"the robot could not answer: {type(exc).__name__}"}
        _answer(query, ok, body)

    def control(self, control: str, raw: bytes) -> tuple[bool, dict]:
        """Carry out one control from the fleet: (True, the console's answer) or (False, {status, error})."""
        from beastbt.live.console_control import Refused, check_answer_body, check_teleop_body, parse_control_body
        if control == "estop":
            return True, self.estop("fleet station")
        try:
            body = parse_control_body(raw)
            if control == "estop_reset":
                return True, self._estop_reset()
            link = self.link
            if link is None or link.run.status is not None:
                raise Refused(409, f"no mission is running on {self.name}")
            if control == "teleop":
                body = check_teleop_body(body)
            elif control == "answer":
                body = check_answer_body(body)
            elif control == "tune":
                from beastbt.live.tuning import check_tune_body
                body = check_tune_body(body)
            elif control == "tune_save":  # the profile's file written here, on Zenoh's thread, not the loop's
                from beastbt.live.tuning import save_through
                return True, save_through(link.controls, CONTROL_TIMEOUT_S)
            future = link.controls.submit(control, body)
            return True, future.result(CONTROL_TIMEOUT_S)
        except Refused as exc:
            return False, {"status": exc.status, "error": str(exc)}
        except FutureTimeout:
            return False, {"status": 503, "error": f"the run did not take '{control}' within {CONTROL_TIMEOUT_S:g} s"}

    def _estop_reset(self) -> dict:
        from beastbt.live.console_control import Refused
        from beastbt.run.safety import reset_estop
        link = self.link
        running = link is not None and link.run.status is None
        if running and link.run.mux.estop_latched:
            reset_estop(link.run, "fleet station")
        elif not self.estop_latched:
            raise Refused(409, "the e-stop is not latched")
        self.estop_latched = False
        return {"estop": False}

    def _on_mission(self, query: Any) -> None:
        payload = _payload(query)
        with self._lock:
            refusal = self._mission_refusal(payload)
            if refusal is None:
                self._pending_mission = True
        if refusal is not None:
            _answer(query, False, refusal)
            return

        def answer(ok: bool, body: dict) -> None:
            if not ok:  # refused (invalid, unreadable): the robot is free before the station hears it, so that
                self.mission_done()  # the mission sent again at once, fixed, is not told the robot is busy
            _answer(query, ok, body)
        self.missions.put(MissionRequest(payload, answer))

    def _mission_refusal(self, payload: bytes) -> Optional[dict]:
        if not self.takes_missions:
            return {"status": 409, "error": f"{self.name} runs one mission ('beastbt run') and takes no other: "
                                            f"run 'beastbt serve' on it to send it missions"}
        if self.link is not None or self._pending_mission:
            if self.link is None:
                return {"status": 409, "error": f"{self.name} is busy checking another mission: send it again in a "
                                                f"moment"}
            return {"status": 409, "error": f"{self.name} is busy with mission '{self.link.run.mission.name}': "
                                            f"abort it first"}
        if self.estop_latched:
            return {"status": 409, "error": f"the e-stop of {self.name} is latched: reset it first (estop_reset)"}
        if not payload.strip():
            return {"status": 400, "error": "the mission is empty: send the mission's YAML (or a zip with its files)"}
        if len(payload) > MISSION_MAX_BYTES:
            return {"status": 413, "error": f"the mission has {len(payload)} bytes: at most {MISSION_MAX_BYTES}"}
        if not payload.startswith(b"PK\x03\x04") and len(payload) > MISSION.max_bytes:
            return {"status": 413, "error": f"the mission's YAML has {len(payload)} bytes: at most "
                                            f"{MISSION.max_bytes} (a mission is a few kB)"}
        return None


def _console_pose(pose: dict) -> dict:
    """A pose ``{x, y, yaw}`` (m, rad CCW from east) as the console's state has it (``x``, ``y``, ``yaw_deg``, and
    ``heading_deg``, clockwise from north)."""
    import math
    yaw_deg = math.degrees(float(pose["yaw"]))
    return {"x": round(float(pose["x"]), 3), "y": round(float(pose["y"]), 3), "yaw_deg": round(yaw_deg, 1),
            "heading_deg": round((90.0 - yaw_deg) % 360.0, 1)}


def _payload(query: Any) -> bytes:
    payload = query.payload
    return bytes(payload.to_bytes()) if payload is not None else b""


def _answer(query: Any, ok: bool, body: dict) -> None:
    """Reply to ``query`` once (JSON) and finish it; a station gone meanwhile is no error."""
    try:
        if ok:
            query.reply(query.key_expr, json.dumps({"ok": True, **body}))
        else:
            query.reply_err(json.dumps({"ok": False, **body}))
    except Exception:  # noqa: BLE001 - the querier has gone (its timeout passed): nothing to answer
        pass
    finally:
        try:
            query.drop()
        except Exception:  # noqa: BLE001
            pass


__all__ = ["FleetAgent", "MissionRequest", "PUBLISH_PERIOD_S", "MISSION_MAX_BYTES"]
