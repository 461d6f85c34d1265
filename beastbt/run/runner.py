"""The tick loop: one run of one mission on one robot, real or simulated.

Each tick: read the clock, advance the simulator (if any), poll every device,
update the estimators, write the blackboard, check e-stop, teleop and
failsafes, tick the tree once, pass the commands through the mux, the
collision monitor (robots with a LiDAR) and the safety gate to the base and
the servos, and record what happened.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable, Mapping, Optional

import py_trees

from beastbt.actuation.gate import GateLimits, SafetyGate, tightest
from beastbt.actuation.mux import CommandMux
from beastbt.behaviours.context import MissionContext, RunServices
from beastbt.blackboard import catalogue
from beastbt.blackboard.types import (BatteryState, CameraFrame, FusedPose, GpsFix, ImuSample, JoystickState,
                                      LaserScan, LineObservation, MapPose, ServoCommand, VelocityCommand, WheelOdometry)
from beastbt.estimation.estimator import Estimator, OdometryEstimator
from beastbt.run.home import Home, HomeFinder
from beastbt.mission.compile import StepBuilder, compile_mission
from beastbt.mission.model import Mission
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.run.operator_inputs import OperatorInputs
from beastbt.run.failsafes import FailsafeMonitor, Situation, failsafe_reads
from beastbt.robot.profile import RobotProfile
from beastbt.robot.robot_io import RobotIO
from beastbt.run.safety import TICK, guard_actuators, guard_collisions
from beastbt.run.tree_ids import TreeNode, tree_layout

Status = py_trees.common.Status

SENSOR_KEYS = ("now_s", "mission_start_s", "odometry", "pose_odom", "pose", "gps_fix", "imu", "battery", "line",
               "camera_frame", "joystick", "home", "cmd_mission", "servo_requests", "servo_angles", "teleop_active",
               "estop", "mux_source", "scan")


@dataclass
class TickRecord:
    """What happened in one tick, handed to recorders (all SI, stamped with the clock)."""

    tick: int
    now_s: float
    readings: list
    pose_odom: Optional[FusedPose]
    pose: Optional[FusedPose]
    cmd_mission: Optional[VelocityCommand]
    cmd_mux: VelocityCommand
    cmd_gate: VelocityCommand
    mux_source: str
    changed_nodes: list[tuple[str, str, str, str]]
    """(node name, new status, feedback message, stable node id) for nodes whose status changed this tick
    (ids: :mod:`beastbt.run.tree_ids`, as in :attr:`MissionRun.layout`)."""
    truth: Optional[Any] = None


TickHook = Callable[["MissionRun", float], None]
"""Called each tick as ``hook(run, now_s)`` after sensing and before the tree (teleop lives here)."""
SummaryContributor = Callable[["MissionRun", dict], None]
"""Adds a part's fields to the run summary: ``fn(run, summary)``."""


class MissionRun:
    """A mission compiled for a robot, ticked by :meth:`tick` until :attr:`status` is set.

    ``status`` is None while running, then ``success``, ``failure`` or ``stopped``.

    The run wires its own safety around ``io``, whoever built it: the command
    mux (with the e-stop latch), the safety gate (speed, turn rate and
    acceleration limits) and the command watchdog around the base
    (:func:`~beastbt.run.safety.guard_actuators`). ``estimator`` fuses the
    sensors (None: wheel odometry alone); ``steps`` are the step builders the
    mission compiles with (None: the language's core steps only).
    """

    def __init__(self, mission: Mission, profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog,
                 services: Optional[RunServices] = None, estimator: Optional[Estimator] = None,
                 steps: Optional[Mapping[str, StepBuilder]] = None) -> None:
        self.mission = mission
        self.profile = profile
        self.io = io
        self.clock = clock
        self.events = events
        catalogue.reset_blackboard()
        self.bb = catalogue.writer("runtime", SENSOR_KEYS)
        self.bb.servo_requests = {}
        self.bb.servo_angles = {}
        self.bb.teleop_active = False
        self.bb.estop = False
        self.ctx = MissionContext(
            clock=clock, events=events, params=profile.control, servo_names=io.servo_names(),
            capabilities=frozenset(io.capabilities),
            speed_limit_mps=tightest(mission.speed_limit_mps, profile.max_speed_mps),
            turn_rate_limit_rps=tightest(mission.turn_rate_limit_rps, profile.max_turn_rate_rps),
            services=services if services is not None else RunServices(),
        )
        self.ctx.services.home = lambda: self.home
        self.root = compile_mission(mission, self.ctx, steps)
        self.nodes = list(self.root.iterate())
        self._last_status = {id(n): n.status for n in self.nodes}
        self.layout: list[TreeNode] = []
        """Every node the run has had, with its stable id: the mission's tree (ids from ``"0"``), then any
        tree put in its place later (a return_home: ids from ``"1"``, so they never clash)."""
        self._node_ids: dict[int, str] = {}
        self._lay_out(self.root)
        self.mux = CommandMux()
        self.gate = SafetyGate(GateLimits(
            max_speed_mps=self.ctx.speed_limit_mps, max_turn_rate_rps=self.ctx.turn_rate_limit_rps,
            max_accel_mps2=tightest(mission.accel_limit_mps2, profile.max_accel_mps2),
            max_angular_accel_rps2=profile.max_angular_accel_rps2, command_timeout_s=profile.command_timeout_s))
        self.watchdog, self.watchdog_checked_by = guard_actuators(io, clock, profile, events)
        self.collision_monitor = guard_collisions(profile, events, self.latest_scan)
        """The collision monitor (profiles with ``lidar:``), applied to every command between the mux and the gate."""
        if self.collision_monitor is not None:
            self.ctx.services.collision_hold = self.collision_monitor.holding  # for a blocked step's reason
        self._no_scan_source_said = False
        self.odom = OdometryEstimator(profile.track_width_m)
        self.estimator: Optional[Estimator] = estimator
        self.failsafes = FailsafeMonitor(mission)
        self.hooks: list[TickHook] = []
        self.reactors: list[TickHook] = []
        """Called by :meth:`react` between ticks when a device wakes the loop (teleop's joystick)."""
        self.recorders: list[Callable[[TickRecord], None]] = []
        self.summary_contributors: list[SummaryContributor] = []
        if self.collision_monitor is not None:
            self.summary_contributors.append(_collision_summary)
        self.recorder: Optional[Any] = None
        """The run's recorder (``beastbt.recording.recorder.McapRecorder``), when it records."""
        self.status: Optional[str] = None
        self.ticks = 0
        self.start_s: Optional[float] = None
        self.home: Optional[tuple[float, float]] = None
        self.home_set: Optional[Home] = None
        """How home was set (the fused start once settled: :mod:`beastbt.run.home`), for the summary; None before."""
        self._home_finder: Optional[HomeFinder] = None
        self.latest: dict[type, Any] = {}
        self.paused_by: Optional[str] = None
        """Why the tree is not ticked now (``hold``, ``teleop``...), or None."""
        self.operator_paused = False
        """The operator pressed pause (the console): the tree is not ticked and the robot is stopped until resume."""
        self.operator_driving = False
        """The operator drives from the console (its stick's deadman is held)."""
        self.inputs = OperatorInputs()
        """What the operator did from outside the tree (console controls, typed answers): recorded for replay."""
        self.read_between_ticks: list = []
        """Readings a reactor took between ticks (:meth:`react`): the next tick's readings start with them."""
        self.ended_by: Optional[str] = None
        """Who ended the run when it was not the mission itself (``operator``: an abort from the console)."""
        self._paused_total_s = 0.0
        self._pause_started_s: Optional[float] = None
        self.failure_handled = False
        self.last_sent: VelocityCommand = VelocityCommand()
        self.want_node_changes = False

    def reads(self) -> frozenset[str]:
        """The blackboard keys (and readings) this run reads: its tree, conditions, failsafes and on_failure.

        What the parts that fill them must keep up to date; the others may
        sleep (:func:`beastbt.robot.part.asleep`).
        """
        keys = set(self.ctx.condition_reads) | failsafe_reads(self.mission)
        for node in self.nodes:
            for client in node.blackboards:
                keys.update(key.lstrip("/") for key in client.read)
        if self.collision_monitor is not None:
            keys.update(("lidar", "scan"))  # the collision monitor reads every scan, whatever the tree does
        return frozenset(keys)

    def latest_scan(self) -> Optional[Any]:
        """The newest ``LaserScan`` polled from ``io.sensors['lidar']`` in this run (None before the first)."""
        return self.latest.get(LaserScan)

    def limit_collisions(self, muxed: VelocityCommand, now: float) -> VelocityCommand:
        """The mux's command through the collision monitor and the safety gate: what may be sent at ``now``.

        The monitor limits the mux's command (so its ratios never compound
        with the gate's ramp), the gate clamps and ramps that; where the
        monitor cut the command, the gate's output is cut to it at once
        (Nav2's monitor also acts after the velocity smoother: a stop is not
        ramped down) and becomes the gate's last output, so motion resumes
        from what was really sent.
        """
        monitor = self.collision_monitor
        if monitor is None:
            return self.gate.filter(muxed, now)
        if "lidar" not in self.io.sensors:
            # A simulator without a LiDAR emulator, or a replay without scans: nothing to monitor with.
            if not self._no_scan_source_said:
                self._no_scan_source_said = True
                self.events.add("collision_monitor", "collision monitor: off: this run has no LiDAR readings "
                                                     "(io.sensors['lidar'])")
            return self.gate.filter(muxed, now)
        limited = monitor.limit(muxed, now)
        out = self.gate.filter(limited, now)
        if limited is muxed:
            return out
        v_max, w_max = abs(limited.linear_mps), abs(limited.angular_rps)
        # (+ 0.0 turns a -0.0 into 0.0: a stop is a plain zero on the wire.)
        out = VelocityCommand(max(-v_max, min(v_max, out.linear_mps)) + 0.0,
                              max(-w_max, min(w_max, out.angular_rps)) + 0.0, out.stamp_s, out.source)
        self.gate.out = out
        return out

    # -- the tick -------------------------------------------------------------
    def tick(self) -> Optional[str]:
        """Run one tick at the clock's current time; return the final status once the run has ended."""
        if self.status is not None:
            return self.status
        now = self.clock.now()
        if self.start_s is None:
            self.events.own()  # listeners run on the thread that ticks, whichever thread built the run
            self.start_s = now
            self.bb.mission_start_s = now
            self.io.base.start(now)
            self.events.add("mission_start", f"mission '{self.mission.name}' started")
        if self.io.sim is not None:
            self.io.sim.advance(now)
        elif self.watchdog_checked_by == TICK:
            self.watchdog.check(now)
        self.events.drain()
        readings = self.sense(now)
        self.bb.cmd_mission = None
        for hook in self.hooks:
            hook(self, now)
        self.check_failsafes(now)
        if self.status is None and not self.mux.estop_latched and self.paused_by is None and not self.operator_paused:
            self.root.tick_once()
            self.after_tree(now)
        if self.mux.estop_latched and self.status is None:
            self.finish("stopped", f"emergency stop: {self.mux.estop_reason}")
        cmd = self.bb.cmd_mission
        if self.paused_by is None and not self.operator_paused and self.status is None:
            self.mux.submit("mission", cmd if cmd is not None else VelocityCommand(0.0, 0.0, now, "mission"), now)
        else:
            self.mux.withdraw("mission")
        self.actuate(now, readings, cmd)
        self.ticks += 1
        return self.status

    def react(self, now: float) -> None:
        """Answer input between ticks (a joystick event): the reactors, then mux, gate and the base at once.

        The tree is not ticked and nothing is recorded: this only lets the
        operator's stick and e-stop reach the wheels without waiting for the
        next tick. The next tick carries on as usual.
        """
        if self.status is not None or not self.reactors:
            return
        for reactor in self.reactors:
            reactor(self, now)
        out = self.limit_collisions(self.mux.select(now), now)
        self._send_velocity(out, now)

    def _send_velocity(self, out: VelocityCommand, now: float) -> None:
        if self.mux.estop_latched:
            if not self.bb.estop:
                self.io.base.emergency_stop(now)
            self.bb.estop = True
        else:
            self.bb.estop = False
        self.io.base.send_velocity(out, now)
        self.last_sent = out
        self.bb.mux_source = self.mux.source

    def sense(self, now: float) -> list:
        """Poll every device, update the estimators and publish everything on the blackboard."""
        # What a reactor read between ticks (the robot's joystick) goes first: it is recorded with this tick.
        readings, self.read_between_ticks = self.read_between_ticks, []
        try:
            readings.extend(self.io.base.poll(now))
        except Exception as exc:  # a driver bug must not stop the loop with the robot moving
            self.events.add("device_error", f"base: {exc!r}")
        for name, poll in self.io.sensors.items():
            try:
                readings.extend(poll(now))
            except Exception as exc:
                self.events.add("device_error", f"{name}: {exc!r}")
        odo, imu, gps = [], [], []
        for r in readings:
            t = type(r)
            self.latest[t] = r
            if t is WheelOdometry:
                odo.append(r)
            elif t is ImuSample:
                imu.append(r)
            elif t is GpsFix:
                gps.append(r)
        bb = self.bb
        bb.now_s = now
        pose_odom = self.odom.update(now, odo)
        bb.pose_odom = pose_odom
        if self.estimator is None:
            # Odometry alone knows where the robot is relative to its start, not in the world.
            pose = replace(pose_odom, heading_valid=False, position_valid=False, lat=None, lon=None)
        else:
            pose = self.estimator.update(now, odo, imu, gps)
        bb.pose = pose
        latest = self.latest
        for key, t in (("odometry", WheelOdometry), ("gps_fix", GpsFix), ("imu", ImuSample), ("battery", BatteryState),
                       ("line", LineObservation), ("camera_frame", CameraFrame), ("joystick", JoystickState),
                       ("scan", LaserScan)):
            if t in latest:
                setattr(bb, key, latest[t])
        if self.home is None:
            finder = self._home_finder
            if finder is None:  # at the first tick: by then the parts have left (or replaced) the estimator
                finder = self._home_finder = HomeFinder(fused=self.estimator is not None, start_odom=pose_odom)
            found = (finder.update(now, gps, pose if self.estimator is not None else None, pose_odom)
                     if gps or finder.had_fix else None)
            if found is not None:
                self.home_set = found
                self.home = (found.lat, found.lon)
                bb.home = self.home
                self.events.add("home", found.text())
        return readings

    def check_failsafes(self, now: float) -> None:
        """Evaluate the failsafes and act on what changed."""
        if not self.failsafes.watches or self.status is not None:
            return
        s = Situation(now, self.start_s or now, self.latest.get(GpsFix), self.latest.get(BatteryState),
                      self.bb.pose, self.home, self.latest.get(MapPose))
        for watch, change in self.failsafes.check(s):
            spec = watch.spec
            if change == "trigger":
                self.events.add("failsafe", f"{spec.kind} triggered: then {spec.then}")
                # a fence's failsafe names the fence: with several fences, which one was crossed is the question
                fence = f" (fence '{spec.params['fence']}')" if "fence" in spec.params else ""
                if spec.then == "stop":
                    self.finish("failure", f"failsafe {spec.kind}: stop{fence}")
                elif spec.then == "hold":
                    self.paused_by = f"hold ({spec.kind})"
                else:
                    handler = self.ctx.services.failsafe.get(spec.then)
                    if handler is None:
                        self.events.add("failsafe", f"'{spec.then}' is not available on this robot: stopping instead")
                        self.finish("failure", f"failsafe {spec.kind}: {spec.then} unavailable{fence}")
                    else:
                        handler(self, spec)
            elif change == "clear":
                self.events.add("failsafe", f"{spec.kind} cleared")
                if self.paused_by is not None and self.paused_by.startswith("hold") and not self.failsafes.holding():
                    self.paused_by = None
                    self.events.add("failsafe", "resuming the mission")

    def after_tree(self, now: float) -> None:
        """Look at the root's status after a tick and decide whether the run ends."""
        status = self.root.status
        if status == Status.SUCCESS:
            self.finish("success", "all steps done")
        elif status == Status.FAILURE:
            self.on_failure(now)

    def on_failure(self, now: float) -> None:
        """The steps failed: do what ``on_failure`` says."""
        tip = self.root.tip()
        why = f"{tip.name}: {tip.feedback_message}" if tip is not None else "a step failed"
        action = self.mission.on_failure
        handler = self.ctx.services.on_failure.get(action) if action != "stop" else None
        if action == "hold":
            teleop = (" or drive it: an operator holding the joystick's enable button has the robot"
                      if "joystick" in self.ctx.capabilities else "")
            ends = ("the simulator's time limit (--max-time, 1 h by default)" if self.io.sim is not None
                    else "--max-time, if given")
            self.events.add("on_failure", f"steps failed ({why}); on_failure: hold: the robot stands still and "
                                          f"waits for the run to be ended: Ctrl-C, SIGTERM or {ends}{teleop}")
            self.paused_by = "on_failure hold"
            self.failure_handled = True
        elif handler is not None:
            self.events.add("on_failure", f"steps failed ({why}); {action}")
            handler(self)
            self.failure_handled = True
        else:
            if action != "stop":
                self.events.add("on_failure", f"'{action}' is not available on this robot; stopping")
            self.finish("failure", f"steps failed: {why}")

    def actuate(self, now: float, readings: list, cmd_mission: Optional[VelocityCommand]) -> None:
        """Mux, gate, and send the velocity and any new servo requests; then record."""
        muxed = self.mux.select(now)
        out = self.limit_collisions(muxed, now)
        if self.status is not None:
            # The run has ended: the last thing sent is a stop, not a ramp down.
            out = VelocityCommand(0.0, 0.0, now, "end")
            self.gate.reset()
        self._send_velocity(out, now)
        requests = self.bb.servo_requests
        if requests:
            angles = self.bb.servo_angles
            for key, sc in list(requests.items()):
                self.send_servo(sc, now)
                if sc.angle_rad is not None:
                    angles[key] = sc.angle_rad
            self.bb.servo_requests = {}
        if self.recorders:
            changed = self.node_changes()
            rec = TickRecord(self.ticks, now, readings, self.bb.pose_odom, self.bb.pose, cmd_mission, muxed, out,
                             self.mux.source, changed, self.io.sim.truth if self.io.sim is not None else None)
            for r in self.recorders:
                r(rec)

    def send_servo(self, cmd: ServoCommand, now: float) -> None:
        """Give a servo command to the first adapter that takes it."""
        for adapter in self.io.servos:
            if adapter.set_servo(cmd, now):
                return
        self.events.add("servo", f"no servo adapter took {cmd}")

    def node_changes(self) -> list[tuple[str, str, str, str]]:
        """Nodes whose status changed since the last call: (name, status, feedback, stable node id)."""
        out = []
        ids = self._node_ids
        for n in self.nodes:
            key = id(n)
            if self._last_status.get(key) != n.status:
                self._last_status[key] = n.status
                node_id = ids.get(key)
                if node_id is None:  # a tree put in after the start (a return_home replacing the mission's)
                    self._lay_out(self.root)
                    if key not in ids:  # a node outside the root's tree: its own root number, still an id
                        self._lay_out(n)
                    node_id = ids[key]
                out.append((n.name, n.status.value, n.feedback_message, node_id))
        return out

    # -- the operator ---------------------------------------------------------------
    def pause(self, who: str) -> bool:
        """Hold the mission where it is, with the robot stopped (any step keeps its place); False if already paused."""
        if self.status is not None or self.operator_paused:
            return False
        self.operator_paused = True
        self._pause_started_s = self.clock.now()
        self.events.add("pause", f"paused by {who}: the robot stops and the mission waits at {self.current_step()}")
        return True

    def resume(self, who: str) -> bool:
        """Go on with the mission after :meth:`pause`; False when it was not paused."""
        if self.status is not None or not self.operator_paused:
            return False
        self.operator_paused = False
        if self._pause_started_s is not None:
            self._paused_total_s += self.clock.now() - self._pause_started_s
            self._pause_started_s = None
        self.events.add("pause", f"resumed by {who} at {self.current_step()}")
        return True

    def abort(self, who: str) -> bool:
        """End the run now (status ``stopped``, robot stopped, summary and recording as usual); False if it had ended."""
        if self.status is not None:
            return False
        self.ended_by = "operator"
        self.finish("stopped", f"aborted by {who}")
        return True

    @property
    def mission_time_s(self) -> float:
        """Seconds the mission has been under way: clock time since the start, less the operator's pauses."""
        paused = self._paused_total_s
        if self._pause_started_s is not None:
            paused += self.clock.now() - self._pause_started_s
        return max(0.0, self.elapsed_s - paused)

    def tree_nodes(self) -> list[TreeNode]:
        """Every node the run has had, parents first, each with its stable id (a tree put in since included)."""
        if id(self.root) not in self._node_ids:
            self._lay_out(self.root)
        return self.layout

    def _lay_out(self, root: py_trees.behaviour.Behaviour) -> None:
        """Give the nodes under ``root`` that have none a stable id, under the next free root number.

        The layout keeps every node it saw alive, so ``id(node)``, the key,
        is never reused by a new node while the run lasts.
        """
        prefix = str(len({n.id.split(".", 1)[0] for n in self.layout}))
        given: dict[str, str] = {}  # path under ``root`` -> the id its node has (new, or the one it had)
        for n in tree_layout(root):
            node_id = self._node_ids.get(id(n.node))
            if node_id is None:
                node_id = prefix + n.id[1:]
                self._node_ids[id(n.node)] = node_id
                self.layout.append(replace(n, id=node_id, parent=given.get(n.parent) if n.parent else None))
            given[n.id] = node_id

    # -- the end ----------------------------------------------------------------
    def current_step(self) -> str:
        """The name of the leaf the tree is running now (or why it is paused)."""
        if self.operator_paused:
            return "(paused)"
        if self.paused_by is not None:
            return f"({self.paused_by})"
        tip = self.root.tip()
        return tip.name if tip is not None else "-"

    def finish(self, status: str, why: str) -> None:
        """End the run with ``status``; the robot is told to stop."""
        if self.status is not None:
            return
        self.status = status
        self.mux.withdraw("mission")
        self.events.add("mission_end", f"{status}: {why}")
        if self.root.status == Status.RUNNING:
            self.root.stop(Status.INVALID)

    def stop_robot(self, now: float) -> None:
        """Send zero to the base (at the end of a run, whatever the reason)."""
        zero = VelocityCommand(0.0, 0.0, now, "shutdown")
        try:
            self.io.base.send_velocity(zero, now)
        except Exception as exc:
            self.events.add("device_error", f"base: could not send the final stop: {exc!r}")
        self.last_sent = zero

    @property
    def elapsed_s(self) -> float:
        """Seconds since the mission started (clock time)."""
        return 0.0 if self.start_s is None else self.clock.now() - self.start_s

    def pose_text(self) -> str:
        """The pose for a status line: odometry x, y, heading in degrees, speed."""
        p = self.bb.pose_odom if self.estimator is None else self.bb.pose
        if p is None:
            return "pose ?"
        return f"x {p.x:6.2f} y {p.y:6.2f} yaw {math.degrees(p.yaw):6.1f} deg  {p.speed_mps:4.2f} m/s"


def _collision_summary(run: MissionRun, summary: dict) -> None:
    """The collision monitor's fields in the run summary (``collision_monitor``)."""
    if run.collision_monitor is not None:
        summary["collision_monitor"] = run.collision_monitor.summary()


__all__ = ["MissionRun", "TickRecord", "TickHook", "SummaryContributor"]
