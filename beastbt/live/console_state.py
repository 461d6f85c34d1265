"""What the operator console shows: the run's state as JSON, and the map's fixed layers.

:class:`ConsoleState` is called on the tick thread (a tick hook). At most
``period_s`` of wall time apart it builds the state object of the console's
contract (``GET /api/state``, ``WS /api/ws``) and hands it over whole; the
web server only ever reads the last one handed over, so the loop never waits
for a viewer and a viewer never sees a half-built state.

The map is drawn in a plan of east-north-up metres (:class:`MapFrame`): on the
simulator the world's own frame (walls, line track, start), on a robot the
navigation filter's frame once it has a fix (places and fences need a datum),
else the odometry frame. The pose in the state is in that plan too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional

import py_trees

from beastbt.blackboard import catalogue
from beastbt.blackboard.types import COST_INSCRIBED, COST_LETHAL, BatteryState, GpsFix, MapPose
from beastbt.estimation.geodesy import LocalFrame
from beastbt.live.tuning import tuning_of
from beastbt.run.progress import progress_of

STATUS_NAMES = {"success": "succeeded", "failure": "failed", "stopped": "aborted"}
"""The run's ending (the summary's ``status``) -> the console's status word."""
NODE_STATUS = {py_trees.common.Status.RUNNING: "running", py_trees.common.Status.SUCCESS: "success",
               py_trees.common.Status.FAILURE: "failure", py_trees.common.Status.INVALID: "idle"}
"""py_trees status -> the tree's status word in the console."""
TRAIL_STEP_M = 0.05
"""A trail point is kept when the robot has moved this far from the last one (m)."""
TRAIL_EVERY_TICKS = 5
"""The trail looks at the pose every this many ticks (0.25 s at 20 Hz): cheap, and fine enough to draw."""
TRAIL_MAX_POINTS = 4000
"""Above this the trail keeps every other point (the page's drawing cost stays bounded)."""
EVENTS_SHOWN = 12
"""The newest events in the state (the page's log); all of them are in the summary and the recording."""
QUIET_EVENTS = frozenset({"asleep", "camera_backend"})
"""Events of the set-up that an operator does not need to read during the run."""
GPS_UERE_M = 4.0
"""Without a covariance, the GPS accuracy circle is HDOP times this (m, a plain receiver's range error)."""
CELL_FULL_V = 4.2
CELL_EMPTY_V = 3.3
"""A Li-ion cell's voltage full and empty (V): the battery's percent is read off this line."""


def board(run: Any, key: str) -> Any:
    """The run's blackboard value ``key``, or None before anything wrote it (the state is built before the first tick)."""
    try:
        return getattr(run.bb, key)
    except KeyError:
        return None


MAX_SCAN_POINTS = 240
"""The scan on the map keeps at most this many of a revolution's points (every k-th): the state stays a few kB."""
MAX_COSTMAP_CELLS = 300
"""The costmap on the map keeps at most this many of its occupied cells (every k-th)."""
SCAN_SHOWN_S = 1.0
"""A scan older than this is not drawn (the LiDAR went silent), s."""


def _mounting(run: Any) -> Any:
    """Where the run's LiDAR sits on base_link (the collision monitor's, else the profile's), or None without one."""
    monitor = run.collision_monitor
    if monitor is not None:
        return monitor.mounting
    if run.profile.section("lidar") is None:
        return None
    from beastbt.robot.profile import section_config
    from beastbt.devices.lidar_scan import LidarConfig
    try:
        return section_config(run.profile, "lidar", LidarConfig).mounting
    except Exception:  # noqa: BLE001 - the run checked its profile; a drawing must never fail the page
        return None


def _to_plan(points: Any, x: float, y: float, yaw: float) -> list:
    """(n, 2) points of a frame whose origin is at (x, y, yaw) on the plan, as [[x, y], ...] rounded to cm."""
    import numpy as np
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    c, s = math.cos(yaw), math.sin(yaw)
    # One product and one shift (a state is built ten times a second, with the scan's hundreds of points).
    out = pts @ np.array([[c, s], [-s, c]])
    out += (x, y)
    return np.round(out, 2).tolist()


def _costmap_cells(costmap: Any, odom_on_plan: tuple[float, float, float]) -> dict:
    """The centres of a costmap's lethal and inscribed cells on the plan (see :func:`obstacle_layers`)."""
    import numpy as np
    rows, cols = np.nonzero((costmap.cost >= COST_INSCRIBED) & (costmap.cost <= COST_LETHAL))
    step = max(1, -(-len(rows) // MAX_COSTMAP_CELLS))
    res = float(costmap.resolution_m)
    centres = np.column_stack((costmap.origin_x_m + (cols[::step] + 0.5) * res,
                               costmap.origin_y_m + (rows[::step] + 0.5) * res))
    return {"cells": _to_plan(centres, *odom_on_plan), "resolution_m": res}


def obstacle_layers(run: Any, frame: "MapFrame", board_client: Any, now_s: float,
                    pose: Optional[tuple[float, float, float]], global_layer: Any = None) -> dict:
    """What the map draws of obstacles now, on the plan (metres, rounded to cm): each key None when there is none.

    ``scan``: the latest LiDAR revolution's returns (at most :data:`MAX_SCAN_POINTS`);
    ``zones``: the collision monitor's stop and slow polygons round the robot and its ``action``;
    ``plan``: the local planner's path (``local_plan``, odom frame, put on the plan through the robot's pose in
    both); ``blocked``: the planner finds no way; ``costmap``: ``{cells, resolution_m}``, the centres of the
    local costmap's cells an obstacle is in or the footprint would touch (Nav2's lethal and inscribed, at most
    :data:`MAX_COSTMAP_CELLS`); ``persons``: the simulator's persons where they are, ``[x, y, radius]``;
    ``path``: the path planned on the mission's saved map (``global_plan``), or the way round a GPS go_to
    follows (``GlobalNavigator.following``, odom), on the plan; ``global_costmap``: with ``global_layer`` (a
    :class:`~beastbt.recording.global_views.ConsoleGlobalLayer`), the global costmap's marked cells as an image
    placed like ``saved_map`` (``png``, ``corner``, ``yaw_rad``, ``width_m``, ``height_m``).
    """
    from beastbt.recording.obstacle_views import fresh, sim_contact
    out: dict = {"scan": None, "zones": None, "plan": None, "blocked": False, "costmap": None, "persons": None,
                 "path": None, "global_costmap": None}
    on_plan = frame.map_on_plan()
    global_plan = catalogue.get(board_client, "global_plan") if on_plan is not None else None
    if global_plan is not None and len(global_plan.points_xy) >= 2:
        # the path go_to follows on the saved map, moved onto the plan
        out["path"] = _to_plan(global_plan.points_xy, *on_plan)
    if pose is not None:
        px, py, pyaw = pose
        scan = run.latest_scan()
        mounting = _mounting(run) if scan is not None else None
        if scan is not None and mounting is not None and now_s - scan.stamp_s <= SCAN_SHOWN_S:
            from beastbt.devices.lidar_scan import base_points_xy
            pts = base_points_xy(scan, mounting)
            step = max(1, -(-len(pts) // MAX_SCAN_POINTS))
            out["scan"] = _to_plan(pts[::step], px, py, pyaw)
        monitor = run.collision_monitor
        if monitor is not None:
            cfg = monitor.config
            out["zones"] = {"stop": _to_plan(monitor.stop_polygon, px, py, pyaw) if cfg.stop.enabled else None,
                            "slow": _to_plan(monitor.slow_polygon, px, py, pyaw) if cfg.slow.enabled else None,
                            "action": monitor.action}
        # odom -> plan: the robot's pose on the plan after the inverse of its pose in odom.
        odo = run.odom
        yaw = pyaw - odo.yaw
        c, s = math.cos(yaw), math.sin(yaw)
        odom_on_plan = (px - (c * odo.x - s * odo.y), py - (s * odo.x + c * odo.y), yaw)
        plan = fresh(catalogue.get(board_client, "local_plan"), now_s)
        if plan is not None and len(plan.points_xy) >= 2:
            out["plan"] = _to_plan(plan.points_xy, *odom_on_plan)
            out["blocked"] = bool(plan.blocked)
        costmap = fresh(catalogue.get(board_client, "costmap"), now_s)
        if costmap is not None:
            out["costmap"] = _costmap_cells(costmap, odom_on_plan)
        local = run.ctx.services.local_navigator
        way = getattr(getattr(local, "global_nav", None), "following", None)
        if way is not None and out["path"] is None:  # the way round a GPS go_to follows (odom)
            out["path"] = _to_plan(way.points, *odom_on_plan)
        drawn = global_layer.now(run, now_s) if global_layer is not None else None
        if drawn is not None:
            out["global_costmap"] = _global_costmap_on_plan(drawn, frame, odom_on_plan)
    contact = sim_contact(run)
    if contact is not None and contact.persons:
        # The simulator's world is the plan (MapFrame): the persons are drawn where they stand.
        out["persons"] = [[round(float(x), 2), round(float(y), 2), p.radius_m]
                          for (x, y), p in zip(contact.person_xy.tolist(), contact.persons)]
    return out


def _global_costmap_on_plan(drawn: tuple[str, dict], frame: "MapFrame",
                            odom_on_plan: tuple[float, float, float]) -> Optional[dict]:
    """The console's global costmap layer (``(frame, layer)`` of ``ConsoleGlobalLayer.now``) placed on the plan:
    its corner moved from odom (GPS) or the saved map's frame onto the plan, with the frame's yaw there."""
    kind, layer = drawn
    x, y = layer["corner"]
    if kind == "map":
        on_plan = frame.map_on_plan()
        if on_plan is None:
            return None
        corner, yaw = frame.map_point(x, y), on_plan[2]
    else:
        corner, yaw = _to_plan([[x, y]], *odom_on_plan)[0], odom_on_plan[2]
    return {"png": layer["png"], "corner": corner, "yaw_rad": round(yaw, 6), "width_m": layer["width_m"],
            "height_m": layer["height_m"]}


def battery_percent(volts: float, cells: Optional[int] = None) -> float:
    """Charge left, percent, from the pack voltage (V); ``cells`` in series (None: guessed at 3.7 V a cell)."""
    n = cells or max(1, round(volts / 3.7))
    return max(0.0, min(100.0, (volts / n - CELL_EMPTY_V) / (CELL_FULL_V - CELL_EMPTY_V) * 100.0))


class MapFrame:
    """Where the console draws: a plan in ENU metres (see the module docstring)."""

    def __init__(self, run: Any, world: Any) -> None:
        self.run = run
        self.world = world
        self.start = (world.start_x, world.start_y, world.start_yaw) if world is not None else (0.0, 0.0, 0.0)
        self.fused = run.estimator is not None and "pose" in run.reads()
        """Show the fused pose (a mission that navigates by it); else odometry from the start, as the steps drive."""

    @property
    def geo(self) -> Optional[LocalFrame]:
        """The datum that places latitude and longitude on the plan (None until a robot has a fix)."""
        if self.world is not None:
            return self.world.frame
        return getattr(self.run.estimator, "frame", None)

    def map_on_plan(self) -> Optional[tuple[float, float, float]]:
        """The pose (x m, y m, yaw rad) of the mission's saved map frame on the plan: the robot started at the
        plan's start and at the mission's start on the map (``start:``); None without ``map:``."""
        mission = getattr(self.run, "mission", None)
        if getattr(mission, "map_grid", None) is None:
            return None
        mx, my, myaw = mission.map_start
        sx, sy, syaw = self.start
        yaw = syaw - myaw
        c, s = math.cos(yaw), math.sin(yaw)
        return sx - (c * mx - s * my), sy - (s * mx + c * my), yaw

    def map_point(self, x: float, y: float) -> list[float]:
        """A point of the saved map's frame (m) on the plan, [x, y] m (a mission with ``map:``)."""
        on_plan = self.map_on_plan()
        assert on_plan is not None
        ox, oy, yaw = on_plan
        c, s = math.cos(yaw), math.sin(yaw)
        return [round(ox + c * x - s * y, 3), round(oy + s * x + c * y, 3)]

    def pose(self) -> Optional[tuple[float, float, float]]:
        """The robot's pose on the plan (x, y m, yaw rad CCW from east), as the robot believes it.

        On a mission with a saved map, its pose on the map (``map_pose``, the
        localiser's), moved onto the plan, so that it is drawn where it is on
        the map drawn under it.

        A mission that navigates by the fused pose (GPS, IMU and odometry) is
        shown by it; one that drives by odometry by its odometry, placed at
        the world's start (on a robot, at the origin).
        """
        on_map = self.run.latest.get(MapPose) if self.map_on_plan() is not None else None
        if on_map is not None:
            x, y = self.map_point(on_map.x, on_map.y)
            return x, y, self.map_on_plan()[2] + on_map.yaw  # type: ignore[index]
        fused = board(self.run, "pose") if self.fused else None
        geo = self.geo
        if fused is not None and fused.position_valid and fused.lat is not None and geo is not None:
            x, y, _ = geo.to_enu(fused.lat, fused.lon, 0.0)
            return x, y, fused.yaw
        odo = self.run.odom  # the odometry integrator itself: read each few ticks, the blackboard is too slow
        sx, sy, syaw = self.start  # odometry starts at the start pose
        c, s = math.cos(syaw), math.sin(syaw)
        return sx + c * odo.x - s * odo.y, sy + s * odo.x + c * odo.y, syaw + odo.yaw

    def point(self, lat: float, lon: float) -> Optional[list[float]]:
        """A WGS84 point (deg) on the plan, [x, y] m; None without a datum."""
        geo = self.geo
        if geo is None:
            return None
        x, y, _ = geo.to_enu(lat, lon, 0.0)
        return [round(x, 3), round(y, 3)]


def map_layers(run: Any, world: Any, frame: MapFrame) -> dict:
    """The map's fixed layers: walls, obstacles, line track, start, places, the mission's waypoints and fences (plan
    metres); with ``map:``, the saved map under them (:func:`saved_map_layer`)."""
    from beastbt.sim.floor import floor_lines
    from beastbt.sim.obstacles import obstacle_outline
    mission = run.mission
    out: dict = {"datum": None, "walls": [], "obstacles": [], "track": [], "start": None, "places": [], "waypoints": [],
                 "fences": []}
    geo = frame.geo
    if geo is not None:
        out["datum"] = {"lat": geo.lat0_deg, "lon": geo.lon0_deg}
    if world is not None:
        out["walls"] = [[w.x1, w.y1, w.x2, w.y2] for w in world.walls]
        out["obstacles"] = [obstacle_outline(o) for o in world.obstacles]
        floor = world.section("floor")
        try:
            out["track"] = [{"points": [[round(float(x), 3), round(float(y), 3)] for x, y in line.points],
                             "closed": line.closed} for line in (floor_lines(floor) if floor else [])]
        except ValueError:
            out["track"] = []  # the world was checked before the run; a drawing must never fail the page
        out["start"] = {"x": world.start_x, "y": world.start_y, "yaw_deg": math.degrees(world.start_yaw)}
    on_plan = frame.map_on_plan()
    out["saved_map"] = saved_map_layer(mission.map_grid, frame) if on_plan is not None else None
    for place in mission.places.values():
        if place.lat is None:  # a place on the saved map
            xy = frame.map_point(place.x, place.y) if on_plan is not None else None
        else:
            xy = frame.point(place.lat, place.lon)
        out["places"].append({"name": place.name, "lat": place.lat, "lon": place.lon, "xy": xy,
                              "tolerance_m": place.tolerance_m})
    out["waypoints"] = route_waypoints(run, frame)
    for fence in mission.fences.values():
        out["fences"].append({"name": fence.name, "keep": fence.keep,
                              "points": [frame.point(lat, lon) for lat, lon in fence.corners]})
    return out


SAVED_MAP_RGBA = {"free": (27, 31, 36, 255), "occupied": (200, 204, 208, 255), "unknown": (0, 0, 0, 0)}
"""The saved map's colours on the console's dark plan: free a shade above the background, walls light, unknown
transparent (RGBA)."""


def saved_map_layer(grid: Any, frame: MapFrame) -> dict:
    """The mission's saved map as the console draws it: ``png`` (a data URL, north up: the image's top row is the
    map's last), ``corner`` (the plan position of its lower-left corner, m), ``yaw_rad`` (the map's x axis on the
    plan), ``width_m`` and ``height_m``."""
    import base64

    import cv2
    import numpy as np
    rgba = np.zeros(grid.data.shape + (4,), np.uint8)
    rgba[:] = SAVED_MAP_RGBA["unknown"]
    rgba[grid.free()] = SAVED_MAP_RGBA["free"]
    rgba[grid.occupied()] = SAVED_MAP_RGBA["occupied"]
    ok, png = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgba[::-1]), cv2.COLOR_RGBA2BGRA))
    on_plan = frame.map_on_plan()
    assert ok and on_plan is not None
    corner_yaw = grid.origin_yaw
    return {"png": "data:image/png;base64," + base64.b64encode(png.tobytes()).decode("ascii"),
            "corner": frame.map_point(grid.origin_x, grid.origin_y), "yaw_rad": round(on_plan[2] + corner_yaw, 6),
            "width_m": grid.width_m, "height_m": grid.height_m}


def route_waypoints(run: Any, frame: MapFrame) -> list[dict]:
    """The places the mission drives to, in the order of its steps: ``{name, xy, tolerance_m}``."""
    from beastbt.behaviours.navigation import GoTo, NavConfig
    nav = run.ctx.services.navigation or NavConfig()
    out = []
    from beastbt.behaviours.map_navigation import MapGoTo
    for node in run.nodes:
        if isinstance(node, MapGoTo):
            goal = node.map_target()
            if goal is not None and frame.map_on_plan() is not None:
                out.append({"name": node.place, "step": node.name, "xy": frame.map_point(*goal),
                            "tolerance_m": node.tolerance_m if node.tolerance_m is not None
                            else node.planner.config.default_tolerance_m})
            continue
        if isinstance(node, GoTo):
            try:
                target = node.target()
            except Exception:  # noqa: BLE001 - a target that needs the run (home) may not be known yet
                target = None
            if target is None:
                continue
            out.append({"name": node.place, "step": node.name, "xy": frame.point(target[0], target[1]),
                        "tolerance_m": node.tolerance_m if node.tolerance_m is not None else nav.default_tolerance_m})
    return out


@dataclass
class Published:
    """The last state handed over, with its JSON, and a counter that changes with every hand-over."""

    seq: int
    state: dict


class ConsoleState:
    """Builds the console's state on the tick thread and hands it to ``on_publish`` (the console's link).

    ``wall`` is a monotonic wall clock in seconds (the hand-over rate is for
    people, not for the simulation); ``period_s`` the least time between
    two hand-overs.
    """

    def __init__(self, run: Any, world: Any, wall: Callable[[], float], period_s: float = 0.1,
                 battery_cells: Optional[int] = None) -> None:
        self.run = run
        self.world = world
        self.wall = wall
        self.period_s = period_s
        self.battery_cells = battery_cells
        self.frame = MapFrame(run, world)
        self.on_publish: Optional[Callable[[int, dict], None]] = None
        """Called with each new state (seq, state) on the thread that built it (the console's link)."""
        self.trail: list[list[float]] = []
        self.map_version = 0
        """Changes when the map's fixed layers change (the datum became known, the home was set)."""
        self._map_key: Optional[tuple] = None
        self._layers: dict = {}
        self._layers_key: Optional[tuple] = None
        from beastbt.recording.global_views import ConsoleGlobalLayer
        from beastbt.recording.obstacle_views import board_reader
        self._board = board_reader()
        self._detections: Any = None
        """The detectors' frame entries (:mod:`beastbt.vision.detection_feed`), once the run's vision watch is seen."""
        self._shown: Optional[dict] = None
        """The newest frame entry, drawn over the video until the detectors sleep."""
        self._global_layer = ConsoleGlobalLayer()
        from beastbt.live.console_photos import PhotoNotes
        self.photos = PhotoNotes(run)
        """The run's photos and newest alert in the state; the photos' files for the console's process."""
        self._published = Published(0, self.build())
        self._last_wall = -math.inf
        self._ticks = 0

    # -- the tick thread --------------------------------------------------------------
    def __call__(self, run: Any, now_s: float) -> None:
        """A tick hook: keep the trail; hand over a new state at most every ``period_s`` (wall)."""
        self._ticks += 1
        if self._ticks % TRAIL_EVERY_TICKS == 0:
            self._extend_trail()
        wall = self.wall()
        if wall - self._last_wall >= self.period_s:
            self._last_wall = wall
            self.publish()

    def publish(self) -> None:
        """Build the state now and hand it over (the tick thread; also for the final state)."""
        state = self.build()
        self._published = Published(self._published.seq + 1, state)
        if self.on_publish is not None:
            self.on_publish(self._published.seq, state)

    def _extend_trail(self) -> None:
        pose = self.frame.pose()
        if pose is None:
            return
        x, y = pose[0], pose[1]
        trail = self.trail
        if not trail or math.hypot(x - trail[-1][0], y - trail[-1][1]) >= TRAIL_STEP_M:
            trail.append([round(x, 3), round(y, 3)])
            if len(trail) > TRAIL_MAX_POINTS:
                self.trail = trail[::2]

    def status_word(self) -> str:
        """``running``, ``paused``, ``succeeded``, ``failed`` or ``aborted``."""
        run = self.run
        if run.status is not None:
            return STATUS_NAMES.get(run.status, run.status)
        return "paused" if run.operator_paused or run.paused_by is not None else "running"

    def build(self) -> dict:
        """The state object of the console's contract (JSON-ready)."""
        run = self.run
        pose = self.frame.pose()
        odo = board(run, "pose_odom")
        fix = run.latest.get(GpsFix)
        battery = run.latest.get(BatteryState)
        questions = self.run.ctx.services.questions
        question = questions.current() if questions is not None else None
        mission_time = run.mission_time_s
        progress = progress_of(run.root, mission_time)
        override = run.ctx.services.teleop
        tip = run.root.tip()
        at_step = tip.name if tip is not None else None
        step = run.current_step()
        if step.startswith("(") and at_step is not None:
            step = f"{at_step} {step}"  # paused: the step it is paused in, and who paused it
        state: dict = {
            "mission": run.mission.name,
            "status": self.status_word(),
            "time_s": round(mission_time, 2),
            "step": step,
            "last_step": at_step,
            "progress": progress.as_dict(),
            "pose": None if pose is None else {
                "x": round(pose[0], 3), "y": round(pose[1], 3), "yaw_deg": round(math.degrees(pose[2]), 1),
                "heading_deg": round((90.0 - math.degrees(pose[2])) % 360.0, 1)},
            "gps": None if fix is None else {
                "lat": fix.lat, "lon": fix.lon, "fix": fix.quality, "sats": fix.sats, "hdop": fix.hdop,
                "accuracy_m": round(_accuracy_m(fix), 2), "xy": self.frame.point(fix.lat, fix.lon)},
            "speed_mps": round(abs(odo.speed_mps), 3) if odo is not None else 0.0,
            "battery": None if battery is None else {
                "volts": round(battery.voltage_v, 2),
                "percent": round(battery_percent(battery.voltage_v, self.battery_cells), 0)},
            "estop": bool(run.mux.estop_latched),
            "teleop": bool(getattr(override, "teleop", None) is not None and override.teleop.active),
            "question": None if question is None else {
                "id": question.id, "text": question.text, "choices": list(question.choices)},
            "tree": [{"id": n.id, "name": n.name, "kind": n.kind, "status": NODE_STATUS.get(n.node.status, "idle"),
                      "parent": n.parent} for n in run.tree_nodes()],
            "ended_at": None,
            "events": [{"time_s": round(e.time_s, 1), "kind": e.kind, "text": e.text}
                       for e in run.events.events[-EVENTS_SHOWN:] if e.kind not in QUIET_EVENTS],
            "command": {"linear_mps": round(run.last_sent.linear_mps, 3),
                        "angular_rps": round(run.last_sent.angular_rps, 3)},
            "sim_time_s": round(run.elapsed_s, 2),
            "mux_source": run.mux.source,
            "paused_by": "operator" if run.operator_paused else run.paused_by,
            "trail_len": len(self.trail),
            "map_version": self._current_map_version(),
            "obstacles": obstacle_layers(run, self.frame, self._board, run.clock.now(), pose, self._global_layer),
            # live tuning's values and the line's error (beastbt.live.tuning); from the first tick, once every part
            # has put in what the knobs bind to
            "tuning": tuning_of(run).state() if run.ticks > 0 else None,
            "detections": self._detections_now(run),
            **self.photos.state(),  # photos: {count, latest: [{name, time_s, url}]}; alert: {time_s, text, photo}
        }
        if run.status is not None:
            last = getattr(self, "_published", None)
            if run.root.status == py_trees.common.Status.INVALID and last is not None:
                # The tree was reset at the end (an abort, an e-stop): show it, and its step, as they were.
                state["tree"], state["last_step"] = last.state["tree"], last.state.get("last_step")
            state["step"] = f"ended: {state['status']}"
            state["ended_at"] = state["last_step"]
        return state

    def _detections_now(self, run: Any) -> Optional[dict]:
        """What the detectors found in the newest frame they looked at (a frame entry of
        :mod:`beastbt.vision.detection_feed`: pixels of a frame ``size`` wide and high), for the page to draw over
        the video; None while no detector is awake (and for a mission that never wakes one)."""
        feed = self._detections
        if feed is None:
            watch = getattr(run.ctx.services, "vision", None)
            if watch is None:
                return None
            from beastbt.vision.detection_feed import DetectionFeed
            feed = self._detections = DetectionFeed.attach(watch)
        entries = feed.take(run.clock.now())
        if entries:
            self._shown = None if entries[-1]["seq"] < 0 else entries[-1]
        return self._shown

    def _current_map_version(self) -> int:
        key = self._layers_key_now()
        if key != self._map_key:
            self._map_key = key
            self.map_version += 1
        return self.map_version

    def latest(self) -> Published:
        """The last state handed over."""
        return self._published

    def _layers_key_now(self) -> tuple:
        geo = self.frame.geo
        return (None if geo is None else (geo.lat0_deg, geo.lon0_deg), self.run.home)

    def layers(self) -> dict:
        """The map's fixed layers (:func:`map_layers`), worked out again only when :attr:`map_version` changes."""
        key = self._layers_key_now()
        if key != self._layers_key:
            self._layers, self._layers_key = map_layers(self.run, self.world, self.frame), key
        return self._layers


def state_json(state: dict) -> str:
    """A state as JSON text: with orjson (a tenth of ``json.dumps``'s time for a state with its scan, ten times a
    second), or ``json.dumps`` for what orjson does not take. A NaN is ``null`` (``JSON.parse`` rejects NaN)."""
    import orjson
    try:
        return orjson.dumps(state, option=orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS).decode()
    except TypeError:
        import json
        return json.dumps(state)


def video_caption(state: dict) -> list[str]:
    """The lines the console's video overlay shows for a state: the mission, status and time; the step (at the
    end, that it ended, and the last step)."""
    if not state:
        return []
    ended = state["status"] in STATUS_NAMES.values()
    head = f"{state['mission']}  {'ended: ' if ended else ''}{state['status']}  t {state['time_s']:.1f} s"
    return [head, f"last step: {state.get('ended_at') or '-'}" if ended else f"step: {state['step']}"]


def _accuracy_m(fix: GpsFix) -> float:
    cov = getattr(fix, "covariance_enu", None)
    if cov is not None:
        try:
            return math.sqrt(max(0.0, float(cov[0][0]) + float(cov[1][1])))
        except (TypeError, IndexError, ValueError):
            pass
    return (fix.hdop or 1.0) * GPS_UERE_M


__all__ = ["ConsoleState", "state_json", "MapFrame", "map_layers", "obstacle_layers", "route_waypoints",
           "battery_percent",
           "video_caption", "STATUS_NAMES", "MAX_SCAN_POINTS", "MAX_COSTMAP_CELLS"]
