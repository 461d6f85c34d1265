"""The ROS 2 link of one run: a Zenoh session that speaks rmw_zenoh (or the DDS bridge's format), out and in.

Out: the run's topics (:mod:`beastbt.ros2.topics`) as CDR on their keys, each
message with rmw_zenoh's attachment, every publisher and subscription
announced by its liveliness token so that ``ros2 topic list`` and rviz2 find
them; ``/map`` and ``/tf_static`` transient local (a late rviz2 gets them from
a cache, as from map_server).

In, all carried out on the tick thread, through the paths the console and the
joystick use (no side door):

* ``/cmd_vel`` (Twist; TwistStamped too) is a remote stick to teleop
  (:class:`~beastbt.live.console_control.ConsoleControls`): the deadman is
  held while messages come, the velocity is the stick's deflection times the
  profile's teleop scale (capped there), so the mux puts it at teleop
  priority, the gate limits it, the collision monitor and the e-stop stay in
  charge; when no message came for :data:`DEADMAN_S` (wall time) the stick
  is released and the robot stops at once.
* ``/estop`` (std_msgs/Bool): true latches the e-stop (from anyone: stopping
  is always allowed); false does nothing (an e-stop is reset at the robot,
  the console or the station).
* ``/initialpose``: the map localiser starts again around that pose.
* ``/goal_pose``: handed to ``on_goal`` when the run has one (``beastbt
  serve`` turns it into a planned ``go_to``); otherwise an event says it was
  not taken.

Access (the fleet's rules, docs/fleet.md): with ``--ros2-config FILE`` (TLS,
Zenoh's access control) the link is what that configuration allows. Without
it the link is plain TCP: on loopback it takes commands; listening beyond
loopback it publishes and takes only the e-stop, since anyone on the network
could otherwise drive the robot.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

from beastbt.ros2 import bridge, cdr
from beastbt.ros2 import rmw_zenoh as rz
from beastbt.ros2.topics import INPUTS, TOPICS, RunTopics

DEADMAN_S = 0.5
"""``/cmd_vel`` holds the robot's teleop this long after its last message (wall s), then the robot stops."""
DEFAULT_LISTEN = "tcp/127.0.0.1:7447"
"""Where the link listens by default: Zenoh's port, on this computer only."""
FORMATS = ("rmw_zenoh", "bridge")
DISTROS = ("jazzy", "humble")
TWIST_BYTES = 52
"""A Twist's CDR: the 4-byte header and six float64; a TwistStamped is longer (the bridge's key has no type)."""
MAX_PENDING = 100
"""At most this many received messages (goals, poses, bad ones) wait for the tick thread; more are dropped and
counted, so that a flood cannot stall the ticks (``/cmd_vel`` does not queue: only its newest message counts)."""
STICK_INPUTS = ("cmd_vel", "cmd_vel_stamped")
"""The inputs that are a stick's position: only the newest message counts (module docstring)."""


@dataclass(frozen=True)
class Ros2Options:
    """How the run meets ROS 2 (``--ros2`` and the profile's ``ros2:`` section; docs/ros2.md).

    ``listen`` a Zenoh endpoint the laptop connects to; ``config_file`` a Zenoh
    JSON5 configuration (TLS, access control) taken as written; ``domain`` the
    ROS domain id; ``namespace`` the node's (``/`` or ``/robot1``); ``format``
    ``rmw_zenoh`` or ``bridge``; ``distro`` ``jazzy`` (type hashes in keys) or
    ``humble`` (``TypeHashNotSupported``); ``topics`` the names of
    :data:`~beastbt.ros2.topics.TOPICS` to publish.
    """

    listen: Optional[str] = DEFAULT_LISTEN
    config_file: Optional[str] = None
    domain: int = 0
    namespace: str = "/"
    format: str = "rmw_zenoh"
    distro: str = "jazzy"
    node: str = "beastbt"
    topics: frozenset = field(default_factory=lambda: frozenset(n for n in TOPICS if n != "tf_static"))


def options_from(section: Optional[dict], listen: Optional[str], config_file: Optional[str]) -> Ros2Options:
    """The link's options: the profile's ``ros2:`` section (checked by its schema), then the command line's."""
    s = dict(section or {})
    topics = s.get("topics")
    return Ros2Options(listen=listen or s.get("listen") or DEFAULT_LISTEN,
                       config_file=config_file or s.get("config"), domain=int(s.get("domain", 0)),
                       namespace=str(s.get("namespace", "/")), format=str(s.get("format", "rmw_zenoh")),
                       distro=str(s.get("distro", "jazzy")), node=str(s.get("node", "beastbt")),
                       topics=frozenset(topics) if topics is not None else Ros2Options().topics)


def full_name(namespace: str, name: str) -> str:
    """``/robot1`` + ``scan`` -> ``/robot1/scan`` (``/`` + ``scan`` -> ``/scan``)."""
    ns = namespace.strip("/")
    return f"/{ns}/{name}" if ns else f"/{name}"


def takes_commands(options: Ros2Options) -> bool:
    """Whether the link takes commands (module docstring): a configuration of its own, or plain on loopback."""
    if options.config_file:
        return True
    from beastbt.fleet.config import endpoint_host
    from beastbt.live.endpoint import is_loopback
    return options.listen is None or is_loopback(endpoint_host(options.listen))


def session_config(options: Ros2Options) -> Any:
    """The Zenoh configuration: the given file as written (its listen endpoint set when given), else a peer
    listening on ``listen``, with no scouting (nothing else on the network is probed) and no shared memory."""
    import json

    import zenoh
    if options.config_file:
        from beastbt.fleet.config import _load
        config = _load(options.config_file, "--ros2-config")
    else:
        config = zenoh.Config()
        config.insert_json5("mode", json.dumps("peer"))
        config.insert_json5("scouting/multicast/enabled", "false")
        config.insert_json5("scouting/gossip/enabled", "false")
        config.insert_json5("connect/endpoints", "[]")
        # No shared memory: the laptop is another computer, and Zenoh's shared-memory watchdog thread woke the robot
        # for nothing (0.1 % of a core of the 1 % the link may cost; benchmarks/ros2_cpu.py).
        config.insert_json5("transport/shared_memory/enabled", "false")
    if options.listen:
        config.insert_json5("listen/endpoints", json.dumps([options.listen]))
    # Transient local publishers are zenoh-ext AdvancedPublishers, which stamp their samples (as rmw_zenoh's own
    # configuration enables it).
    config.insert_json5("timestamping/enabled", "true")
    return config


class Ros2Link:
    """The link (module docstring) of ``prepared``'s run, opened by :meth:`open` and closed by :meth:`close`."""

    def __init__(self, prepared: Any, options: Ros2Options, wall: Callable[[], float] = time.monotonic,
                 on_goal: Optional[Callable[[cdr.PoseStamped, Any], None]] = None) -> None:
        self.prepared = prepared
        self.run = prepared.run
        self.options = options
        self.wall = wall
        self.on_goal = on_goal
        self.humble = options.distro == "humble"
        self.commands = takes_commands(options)
        self.session: Any = None
        self.zid = ""
        self._pubs: dict[str, Any] = {}
        self._seq: dict[str, int] = {}
        self._gids: dict[str, bytes] = {}
        self._matching: dict[str, bool] = {}
        """Whether a subscriber matches each volatile topic now (Zenoh's matching status, kept by listeners)."""
        self._tokens: list[Any] = []
        self._subs: list[Any] = []
        self.token_keys: list[str] = []
        """The liveliness tokens declared (for the tests and ``beastbt doctor``)."""
        self.keys: dict[str, str] = {}
        """The data key of each published topic."""
        self._pending: "queue.SimpleQueue[tuple[str, Any]]" = queue.SimpleQueue()
        self._sticks: list[tuple[str, Any]] = []
        """``/cmd_vel``'s subscriptions (name, subscriber): Zenoh keeps each one's newest message in a ring of one,
        read at each tick (:meth:`_poll_sticks`), so a flood is one command a tick, runs no Python per message and
        leaves no backlog behind the sender (the deadman counts from the laptop's last message, within a tick)."""
        self.dropped = 0
        """Messages dropped because :data:`MAX_PENDING` waited already."""
        self.controls: Any = None
        self.topics: Optional[RunTopics] = None
        self.received = 0
        self.refused = 0
        self.goals: Any = None
        """The run's :class:`~beastbt.behaviours.ros2_goals.GoalInbox` (a link that takes commands), or None."""
        self._lock = threading.Lock()

    # -- opening -------------------------------------------------------------------------------------------------
    def open(self) -> "Ros2Link":
        """Open the session, declare the node, publishers and subscriptions, and hook into the run."""
        import zenoh
        self.session = zenoh.open(session_config(self.options))
        try:
            self.zid = str(self.session.info.zid())
            self._declare_outputs()
            self._declare_inputs()
        except BaseException:
            self.close()  # nothing half-declared stays behind (the port is freed)
            raise
        run = self.run
        clock = self.prepared.clock
        if self.commands:
            from beastbt.behaviours.ros2_goals import GOAL_INBOX, GoalInbox
            self.goals = run.ctx.services.plugins[GOAL_INBOX] = GoalInbox()  # a ros2_goals step's goals
        self.topics = RunTopics(run, self.prepared.profile, self.options.topics, self._send,
                                time.time() - clock.now(), self.wanted)
        self.topics.start(clock.now())
        run.recorders.append(self.topics.on_tick)
        if self.commands:
            from beastbt.live.console_control import ConsoleControls
            self.controls = ConsoleControls(run, self.wall, stick_timeout_s=DEADMAN_S)
            run.reactors.append(self._apply)
        run.hooks.insert(0, self._apply)  # before the tree: a command counts in this tick
        return self

    def _declare_outputs(self) -> None:
        import zenoh
        o = self.options
        names = set(o.topics) | ({"tf_static"} if "tf" in o.topics else set())
        node = rz.Node(o.domain, self.zid, 0, o.namespace, o.node)
        if o.format == "rmw_zenoh":
            self._token(node.token())
        else:
            self._token(bridge.plugin_token(self.zid))
        for eid, name in enumerate(sorted(names), start=1):
            spec = TOPICS[name]
            topic = full_name(o.namespace, spec.name)
            if o.format == "rmw_zenoh":
                key = rz.topic_key(o.domain, topic, spec.type_name, self.humble)
                token = node.endpoint_token(eid, rz.PUBLISHER, topic, spec.type_name, spec.qos, self.humble)
                self._gids[name] = rz.gid(token)
            else:
                key = bridge.data_key(topic)
                token = bridge.endpoint_token(self.zid, rz.PUBLISHER, key, spec.type_name, spec.qos)
            reliable = spec.qos.reliability == rz.RELIABLE
            kwargs = {"congestion_control": zenoh.CongestionControl.DROP,
                      "reliability": zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT}
            if spec.qos.durability == rz.TRANSIENT_LOCAL:
                import zenoh.ext
                pub = zenoh.ext.declare_advanced_publisher(
                    self.session, key, cache=zenoh.ext.CacheConfig(max_samples=spec.qos.depth),
                    publisher_detection=True, **kwargs)
            else:
                pub = self.session.declare_publisher(key, **kwargs)
                self._watch_matching(name, pub)
            self._pubs[name] = pub
            self._seq[name] = 0
            self.keys[name] = key
            self._token(token)
        self._next_eid = len(names) + 1
        self._node = node

    def _declare_inputs(self) -> None:
        o = self.options
        eid = self._next_eid
        for name, spec in INPUTS.items():
            topic = full_name(o.namespace, spec.name)
            if o.format == "rmw_zenoh":
                # any type hash: a Humble sender writes TypeHashNotSupported, a Jazzy one its RIHS01
                key = rz.topic_key(o.domain, topic, spec.type_name, self.humble).rsplit("/", 1)[0] + "/*"
                token = self._node.endpoint_token(eid, rz.SUBSCRIPTION, topic, spec.type_name, spec.qos, self.humble)
            else:
                if name == "cmd_vel_stamped":
                    continue  # the bridge's key has no type: /cmd_vel's one subscription reads both (by size)
                key = bridge.data_key(topic)
                token = bridge.endpoint_token(self.zid, rz.SUBSCRIPTION, key, spec.type_name, spec.qos)
            if name in STICK_INPUTS:
                import zenoh
                sub = self.session.declare_subscriber(key, zenoh.handlers.RingChannel(1))
                self._sticks.append((name, sub))
            else:
                sub = self.session.declare_subscriber(key, self._receiver(name))
            self._subs.append(sub)
            self._token(token)
            eid += 1

    def _watch_matching(self, name: str, pub: Any) -> None:
        """Keep ``name``'s matching status (a transient local topic is always made: its cache serves late
        subscribers). Without the API (an older eclipse-zenoh) every topic is made."""
        if not hasattr(pub, "declare_matching_listener"):
            return
        matching = self._matching

        def changed(status: Any) -> None:  # Zenoh's thread: one dict item set, read by the tick thread
            matching[name] = bool(status.matching)
        self._subs.append(pub.declare_matching_listener(changed))
        matching[name] = bool(pub.matching_status.matching)

    def wanted(self, name: str) -> bool:
        """Whether a subscriber on the ROS 2 side matches topic ``name`` now: no one, nothing made or sent."""
        return self._matching.get(name, True)

    def _token(self, key: str) -> None:
        self._tokens.append(self.session.liveliness().declare_token(key))
        self.token_keys.append(key)

    # -- out -----------------------------------------------------------------------------------------------------
    def _send(self, name: str, payload: bytes) -> None:
        pub = self._pubs.get(name)
        if pub is None:
            return
        if self.options.format == "rmw_zenoh":
            seq = self._seq[name] = self._seq[name] + 1
            pub.put(payload, attachment=rz.attachment(seq, time.time_ns(), self._gids[name]))
        else:
            pub.put(payload)

    # -- in (Zenoh's threads: decode, then queue for the tick thread) --------------------------------------------
    def _decode(self, name: str, data: bytes) -> Any:
        """The message of input ``name`` in ``data``; :class:`~beastbt.ros2.cdr.CdrError` when it is not one."""
        if name == "cmd_vel_stamped" or (self.options.format == "bridge" and name == "cmd_vel"
                                         and len(data) != TWIST_BYTES):
            return cdr.decode_twist_stamped(data)  # the bridge's key has no type: told by its size
        if name == "cmd_vel":
            return cdr.decode_twist(data)
        if name == "goal_pose":
            return cdr.decode_pose_stamped(data)
        return cdr.decode_pose_with_covariance_stamped(data)

    def _receiver(self, name: str) -> Callable[[Any], None]:
        def receive(sample: Any) -> None:
            data = sample.payload.to_bytes()
            try:
                if name == "estop":
                    if cdr.decode_bool(data):
                        from beastbt.run.safety import request_estop  # safe from any thread
                        request_estop(self.run, "ROS 2 /estop")
                    return
                value = self._decode(name, data)
            except cdr.CdrError as exc:
                self._queue(("bad", f"{name}: {exc}"))
            else:
                self._queue((name, value) if self.commands else ("refused", name))
            self.run.io.wakeup.set()
        return receive

    def _queue(self, item: tuple[str, Any]) -> None:
        """Queue ``item`` for the tick thread, unless :data:`MAX_PENDING` wait already (then it is counted)."""
        if self._pending.qsize() >= MAX_PENDING:
            self.dropped += 1
            return
        self._pending.put(item)

    # -- the tick thread -------------------------------------------------------------------------------------------
    def _poll_sticks(self) -> Optional[cdr.Twist]:
        """The newest ``/cmd_vel`` since the last tick (Twist or TwistStamped), or None; a bad or refused one is
        queued as the other inputs' are."""
        newest = None
        for name, sub in self._sticks:
            sample = sub.try_recv()
            if sample is None:
                continue
            try:
                value = self._decode(name, sample.payload.to_bytes())
            except cdr.CdrError as exc:
                self._queue(("bad", f"{name}: {exc}"))
                continue
            if self.commands:
                newest = value
            else:
                self._queue(("refused", "cmd_vel"))
        return newest

    def _apply(self, run: Any, now_s: float) -> None:
        """A tick hook and a reactor: carry out what came, then the deadman (the stick's own timeout)."""
        pending = self._pending
        controls = self.controls
        twist = self._poll_sticks() if self._sticks else None
        if twist is None and pending.empty() and (controls is None or not controls.stick_held):
            return
        if twist is not None:
            self.received += 1
            self._drive(twist)
        for _ in range(pending.qsize()):  # what waits now: what comes meanwhile is the next tick's
            try:
                kind, value = pending.get_nowait()
            except queue.Empty:
                break
            self.received += 1
            if kind == "initialpose":
                self._initial_pose(run, value)
            elif kind == "goal_pose":
                self._goal(run, value)
            elif kind == "refused":
                self.refused += 1
                if self.refused == 1:
                    run.events.add("ros2", f"ROS 2 {value} not taken: the link listens beyond loopback without keys "
                                           f"(--ros2-config with TLS to command; docs/ros2.md)")
            elif kind == "bad":
                run.events.add("ros2", f"ROS 2 message not understood: {value}")
        if self.dropped:
            run.events.add("ros2", f"{self.dropped} ROS 2 messages dropped: more than {MAX_PENDING} came between two "
                                   f"ticks (a flood)")
            self.dropped = 0
        if controls is not None:
            controls.apply_pending(now_s)

    def _drive(self, twist: cdr.Twist) -> None:
        if self.controls is None:
            return
        override = self.run.ctx.services.teleop
        config = getattr(getattr(override, "teleop", None), "config", None)
        lin_scale = float(getattr(config, "scale_linear_mps", 0.0) or 0.0)
        ang_scale = float(getattr(config, "scale_angular_rps", 0.0) or 0.0)
        linear = twist.linear[0] / lin_scale if lin_scale > 0 else 0.0
        angular = twist.angular[2] / ang_scale if ang_scale > 0 else 0.0
        self.controls.submit("teleop", {"linear": max(-1.0, min(1.0, linear)),
                                        "angular": max(-1.0, min(1.0, angular)), "deadman": True})

    def _initial_pose(self, run: Any, pose: cdr.PoseStamped) -> None:
        loc = run.ctx.services.plugins.get("map_localiser")
        from beastbt.blackboard.types import MapPose
        last = run.latest.get(MapPose)
        if loc is None or last is None:
            run.events.add("ros2", "ROS 2 /initialpose not taken: this run localises on no map")
            return
        from beastbt.estimation.map_localiser import compose, invert
        x, y = pose.position[0], pose.position[1]
        grid = getattr(loc, "grid", None)
        if grid is not None and not (grid.origin_x <= x <= grid.origin_x + grid.width_m
                                     and grid.origin_y <= y <= grid.origin_y + grid.height_m):
            run.events.add("ros2", f"ROS 2 /initialpose ({x:.6g}, {y:.6g}) m not taken: it is off the map (it covers "
                                   f"x {grid.origin_x:.1f} to {grid.origin_x + grid.width_m:.1f} m, y "
                                   f"{grid.origin_y:.1f} to {grid.origin_y + grid.height_m:.1f} m)")
            return
        odom = compose(invert((last.odom_x, last.odom_y, last.odom_yaw)), (last.x, last.y, last.yaw))
        cov = pose.covariance or ()
        sigma_xy = math.sqrt(max(cov[0], cov[7])) if len(cov) == 36 and cov[0] > 0 else 0.5
        sigma_yaw = math.sqrt(cov[35]) if len(cov) == 36 and cov[35] > 0 else math.radians(15.0)
        # A spread no wider than the map, nor than a turn: an infinite or huge covariance (finite CDR still) put the
        # particles nowhere, and the localiser's next estimate divided by zero, ending the run.
        span = max(grid.width_m, grid.height_m) if grid is not None else 10.0
        sigma_xy = min(sigma_xy, span) if math.isfinite(sigma_xy) else span
        sigma_yaw = min(sigma_yaw, math.pi) if math.isfinite(sigma_yaw) else math.pi
        loc.start((x, y, pose.yaw), sigma_xy, sigma_yaw, odom)
        run.events.add("ros2", f"ROS 2 /initialpose: localising again around ({pose.position[0]:.2f}, "
                               f"{pose.position[1]:.2f}) m, {math.degrees(pose.yaw):.0f} deg")

    def _goal(self, run: Any, pose: cdr.PoseStamped) -> None:
        """A goal: to the mission's ``ros2_goals`` step when one runs, else to ``beastbt serve``, else not taken."""
        x, y = pose.position[0], pose.position[1]
        if self.goals is not None and self.goals.listening:
            from beastbt.ros2.goal_steps import goal_in_map_frame
            map_frame = self.topics.frames.map if self.topics is not None else "map"
            if not goal_in_map_frame(pose.frame_id, map_frame):
                run.events.add("ros2", f"ROS 2 /goal_pose ({x:.2f}, {y:.2f}) in frame '{pose.frame_id}' not taken: "
                                       f"goals are planned in the map frame '{map_frame}' (rviz2's Fixed Frame)")
                return
            self.goals.put(x, y)
            return
        if self.on_goal is None:
            run.events.add("ros2", f"ROS 2 /goal_pose ({x:.2f}, {y:.2f}) not taken: goals are taken by a mission's "
                                   f"ros2_goals step or by 'beastbt serve --ros2'")
            return
        self.on_goal(pose, run)

    # -- closing -------------------------------------------------------------------------------------------------
    def close(self) -> None:
        """Undeclare everything and close the session (the laptop sees the node go)."""
        with self._lock:
            session, self.session = self.session, None
        if session is None:
            return
        if self.topics is not None:
            try:
                self.topics.flush()  # the last burst's ticks
            except Exception:  # noqa: BLE001 - closing goes on whatever the last messages were
                pass
        if self.controls is not None:
            self.controls.close()
        for item in self._subs + self._tokens + list(self._pubs.values()):
            try:
                item.undeclare()
            except Exception:  # noqa: BLE001 - closing what is already gone is no error
                pass
        session.close()




# -- beastbt serve: goals between missions -------------------------------------------------------------------------

def goal_mission(pose: cdr.PoseStamped, map_file: Optional[str] = None) -> bytes:
    """The mission a ``/goal_pose`` becomes in ``beastbt serve``: a planned ``go_to`` to that place on
    ``map_file`` (the pose's frame is taken as the map's; the heading is not kept: go_to ends where it arrives)."""
    import json
    x, y = pose.position[0], pose.position[1]
    # The frame comes from the network: quoted (JSON is YAML), so that no frame_id can add keys to the mission.
    description = json.dumps(f"rviz2's 2D Goal Pose ({x:.2f}, {y:.2f}) m in {pose.frame_id or 'map'}")
    return (f"mission: ros2_goal\n"
            f"description: {description}\n"
            + (f"map: {json.dumps(str(map_file))}\n" if map_file else "") +
            f"places:\n  goal: {{x: {x:.3f} m, y: {y:.3f} m}}\n"
            f"steps:\n  - go_to: goal\n").encode()


class GoalListener:
    """``beastbt serve --ros2`` while no mission runs: the node stays in the ROS graph and ``/goal_pose`` is
    taken (each goal handed to ``on_goal``). Closed while a mission runs: its run's link takes over the port."""

    def __init__(self, options: Ros2Options, on_goal: Callable[[cdr.PoseStamped, Any], None]) -> None:
        self.options = options
        self.on_goal = on_goal
        self.session: Any = None
        self._items: list[Any] = []

    def open(self) -> "GoalListener":
        """Open the session, the node's token and the /goal_pose subscription."""
        import zenoh
        o = self.options
        self.session = zenoh.open(session_config(o))
        zid = str(self.session.info.zid())
        humble = o.distro == "humble"
        spec = INPUTS["goal_pose"]
        topic = full_name(o.namespace, spec.name)
        if o.format == "rmw_zenoh":
            node = rz.Node(o.domain, zid, 0, o.namespace, o.node)
            key = rz.topic_key(o.domain, topic, spec.type_name, humble).rsplit("/", 1)[0] + "/*"
            tokens = [node.token(), node.endpoint_token(1, rz.SUBSCRIPTION, topic, spec.type_name, spec.qos, humble)]
        else:
            key = bridge.data_key(topic)
            tokens = [bridge.plugin_token(zid),
                      bridge.endpoint_token(zid, rz.SUBSCRIPTION, key, spec.type_name, spec.qos)]
        for token in tokens:
            self._items.append(self.session.liveliness().declare_token(token))

        def receive(sample: Any) -> None:
            try:
                pose = cdr.decode_pose_stamped(sample.payload.to_bytes())
            except cdr.CdrError:
                return
            self.on_goal(pose, None)
        if takes_commands(o):
            self._items.append(self.session.declare_subscriber(key, receive))
        return self

    def close(self) -> None:
        """Leave the graph and free the port."""
        session, self.session = self.session, None
        if session is None:
            return
        for item in self._items:
            try:
                item.undeclare()
            except Exception:  # noqa: BLE001 - already gone
                pass
        self._items = []
        session.close()


__all__ = ["Ros2Link", "Ros2Options", "GoalListener", "goal_mission", "options_from", "full_name", "takes_commands",
           "session_config", "DEADMAN_S", "DEFAULT_LISTEN", "FORMATS", "DISTROS"]
