"""``beastbt report RUN``: a run at a glance, in the terminal and as plots
(drawn by :mod:`beastbt.recording.report_plots`).

From a run folder (``runs/<time>_<mission>/``) or an ``.mcap`` file:

* a terminal summary: outcome, duration, distance, waypoints with their
  arrival errors and tolerances, failsafes, dropped messages;
* a report folder (``report/`` in the run folder unless ``--out DIR``) with
  PNG plots made with matplotlib (Agg backend, no display needed), each
  titled with the mission's name and the date of the run:
  ``path.png`` (the path on a map in metres, scaled to the true path, the
  line track and the mission's places: the world's walls and line track,
  ground truth when simulated, the fused estimate, odometry, the raw GPS
  fixes when there were any (light, never setting the scale), the places
  with their tolerance circles, the world's obstacles, each person's path
  and where it walked, the collisions), ``clearance.png`` (the gap between
  the footprint and the nearest thing over time: the simulator's truth and
  the LiDAR's nearest return, collisions and the collision monitor's
  actions marked), ``position_error.png`` (fused, odometry
  and raw GPS against truth), ``speeds.png`` (commanded against actual),
  ``line_error.png`` (when a line was followed), ``timeline.png`` (which
  step ran when, one row per node of the tree: steps that share a name
  are told apart by their stable node id), and ``report.html`` showing
  them together with a waypoint table (tolerance; the estimated and the true distance at arrival).

Times are seconds from the run's first tick, whatever the recording's time
base. A plot whose data the run does not have (no truth on the robot, no
GPS, no line) is left out, and the report says so.
"""

from __future__ import annotations


import datetime as _dt
import html
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from beastbt.recording.reader import Recording, find_recording, read_recording
from beastbt.recording.report_plots import (DPI, FIG_SIZE_IN, MAP_SIZE_IN, PLOTS, StepRun, truth_at,
                                           draw_path, map_extent, plot_clearance, plot_line_error, plot_path,
                                           plot_position_error, plot_saved_map, plot_speeds, plot_timeline,
                                           position_errors, step_intervals, timeline_rows)
from beastbt.run.home import home_line
from beastbt.run.summary import obstacles_line, vision_lines, waypoint_text

NOT_PLOTTED = ("/sensors/imu", "/sensors/battery", "/sensors/joystick", "/sensors/camera", "/camera/image",
               "/pose/fused", "/gps/fix", "/log", "/cmd/servo", "/cmd/mux", "/cmd/teleop", "/devices/state",
               # Foxglove's views of what the report reads elsewhere (every tick: decoding them is memory for nothing)
               "/gps/fused", "/tf", "/odom", "/scene", "/route", "/camera/calibration", "/camera/annotations",
               "/costmap", "/local_plan", "/collision_monitor/zones", "/sim/persons", "/localisation/particles",
               "/camera/photo", "/camera/detections", "/camera/tags", "/global_costmap", "/plan",
               "/vision/answers")
"""Topics the report does not decode (counted all the same): the plots do not use them."""


@dataclass
class Report:
    """What ``beastbt report`` made: the summary text, the plots written (name -> path), what was left out."""

    text: str
    folder: Path
    plots: dict[str, Path] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)
    html: Optional[Path] = None


# -- data -----------------------------------------------------------------------------


@dataclass
class Waypoint:
    """One row of the waypoint table: a place a go_to, route or return_home aimed for, and how it went.

    ``lat``/``lon`` in degrees; ``tolerance_m`` how close the step had to come
    (m; the summary's, else the mission's place tolerance or the profile's
    default for a summary from before it was recorded; None when unknown);
    ``arrival_error_m`` the true distance at arrival in the simulator (m, None
    when not reached); ``time_s`` the mission time of arrival (s).
    """

    name: str
    lat: Optional[float]
    lon: Optional[float]
    reached: bool
    tolerance_m: Optional[float]
    arrival_error_m: Optional[float]
    time_s: Optional[float]
    estimated_error_m: Optional[float] = None
    """The fused estimate's distance to the place at arrival (m): what arrival was judged on."""
    true_error_m: Optional[float] = None
    """The true distance at arrival (m, simulator only): the estimate's own error included."""
    x: Optional[float] = None
    y: Optional[float] = None
    """A place on a saved map: where it is in the map frame (m); ``lat``/``lon`` are then None."""


EPOCH_NS_AFTER = 946_684_800 * 10**9
"""Log times past this (2000-01-01 in Unix nanoseconds) are taken as wall-clock dates, not clock seconds."""


@dataclass
class RunData:
    """A recording and its summary, with the series the plots need (seconds, metres, world frame).

    Times are seconds from the run's first tick (its first ``/cmd/gate``
    message; else the first message decoded), whatever the recording's time
    base: the clock's seconds, or Unix nanoseconds.
    """

    rec: Recording
    summary: Optional[dict]
    name: str
    world_start: Optional[tuple[float, float, float]] = None
    datum: Optional[tuple[float, float, float]] = None
    t0_ns: int = 0
    """Log time of the run's first tick, ns: time 0 of every plot."""

    @classmethod
    def load(cls, run: str) -> "RunData":
        """Read the run folder or ``.mcap`` at ``run``."""
        path = find_recording(run)
        rec = read_recording(path, skip_topics=NOT_PLOTTED)
        if not rec.info and not rec.message_count():
            raise ValueError(f"{path}: not a beastbt run recording (no beastbt.run metadata, no messages)")
        summary = None
        folder_summary = path.parent / "summary.json"
        if path.name == "run.mcap" and folder_summary.exists():
            try:
                summary = json.loads(folder_summary.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                summary = None
        if summary is None:
            summary = rec.summary
        name = path.parent.name if path.name == "run.mcap" else path.stem
        data = cls(rec, summary, name)
        info = rec.info
        if info.get("world_start"):
            data.world_start = tuple(json.loads(info["world_start"]))
        if info.get("world_datum"):
            data.datum = tuple(json.loads(info["world_datum"]))
        gates = rec.messages.get("/cmd/gate")
        firsts = [msgs[0][0] for msgs in rec.messages.values() if msgs]
        data.t0_ns = gates[0][0] if gates else (min(firsts) if firsts else 0)
        return data

    def times(self, topic: str) -> list[float]:
        """The log times of a topic's messages, seconds from the run's first tick."""
        t0 = self.t0_ns
        return [(t - t0) * 1e-9 for t, _ in self.rec.messages.get(topic, [])]

    def series(self, topic: str) -> tuple[list[float], list[dict]]:
        """(times in s from the first tick, messages) of a topic."""
        return self.times(topic), self.rec.topic(topic)

    # -- what the run was -------------------------------------------------------------------
    def mission_name(self) -> str:
        """The mission's name (the metadata's, else the summary's, else the run's folder or file name)."""
        return self.rec.info.get("mission") or (self.summary or {}).get("mission") or self.name

    def started_utc(self) -> Optional[_dt.datetime]:
        """When the run started (UTC): the metadata's ``start_utc``, else an epoch time base's first tick."""
        text = self.rec.info.get("start_utc")
        if text:
            try:
                return _dt.datetime.strptime(text, "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=_dt.timezone.utc)
            except ValueError:
                pass
        if self.t0_ns > EPOCH_NS_AFTER:
            return _dt.datetime.fromtimestamp(self.t0_ns * 1e-9, _dt.timezone.utc)
        return None

    def title(self) -> str:
        """The report's title: the mission's name and the date and time the run started."""
        when = self.started_utc()
        return f"{self.mission_name()}, {when:%Y-%m-%d %H:%M} UTC" if when else f"{self.mission_name()}, date unknown"

    # -- the world --------------------------------------------------------------------------
    def attached_yaml(self, name: str) -> Optional[dict]:
        """A YAML file attached to the recording (``world.yaml``, ``robot.yaml``) as a mapping, read once; None
        when it is absent or is not a mapping."""
        cache = self.__dict__.setdefault("_attached_yaml", {})
        if name not in cache:
            cache[name] = None
            text = self.rec.text(name)
            if text is not None:
                import yaml
                try:
                    doc = yaml.safe_load(text)
                except yaml.YAMLError:
                    doc = None
                cache[name] = doc if isinstance(doc, dict) else None
        return cache[name]

    def world_doc(self) -> Optional[dict]:
        """The simulated world file as recorded (``world.yaml`` attachment), or None."""
        return self.attached_yaml("world.yaml")

    def walls(self) -> list[tuple[float, float, float, float]]:
        """The world's walls as (x1, y1, x2, y2) metres: the metadata's, else the recorded world file's."""
        raw = self.rec.info.get("world_walls")
        walls = json.loads(raw) if raw else (self.world_doc() or {}).get("walls") or []
        try:
            return [(float(w[0]), float(w[1]), float(w[2]), float(w[3])) for w in walls]
        except (TypeError, ValueError, IndexError):
            return []

    def track(self) -> list[list[tuple[float, float]]]:
        """The world's painted lines (the line track) as polylines in metres, a closed one back to its start."""
        floor = (self.world_doc() or {}).get("floor")
        if not isinstance(floor, dict):
            return []
        from beastbt.sim.floor import floor_lines
        try:
            lines = floor_lines(floor)
        except ValueError:
            return []  # a world file this version does not read: the map goes without the track
        out = []
        for line in lines:
            pts = [(float(x), float(y)) for x, y in line.points]
            out.append(pts + pts[:1] if line.closed else pts)
        return out

    def obstacles(self) -> list[dict]:
        """The world's obstacles as the maps draw them (world metres): a box's ``corners``, a cylinder's ``xy`` and
        ``radius_m``, a person's ``path`` and ``radius_m`` (:func:`beastbt.sim.obstacles.obstacle_outline`)."""
        raw = self.rec.info.get("world_obstacles")
        try:
            found = json.loads(raw) if raw else []
        except ValueError:
            return []
        return [o for o in found if isinstance(o, dict) and o.get("shape") in ("box", "cylinder", "person")]

    def person_walks(self) -> list[list[tuple[float, float]]]:
        """Where each simulated person walked (world metres), from ``/sim/contact``: one polyline per person."""
        walks: list[list[tuple[float, float]]] = []
        for m in self.rec.topic("/sim/contact"):
            for i, p in enumerate(m.get("persons") or []):
                while len(walks) <= i:
                    walks.append([])
                if not walks[i] or walks[i][-1] != (p[0], p[1]):
                    walks[i].append((p[0], p[1]))
        return walks

    def collisions(self) -> list[tuple[float, Optional[tuple[float, float]]]]:
        """(time s, true position m or None) of each new contact in the simulator (``/sim/contact``'s count rising)."""
        out: list[tuple[float, Optional[tuple[float, float]]]] = []
        last = 0
        truth = self.rec.topic("/truth")
        for t, m in zip(*self.series("/sim/contact")):
            n = int(m.get("collisions") or 0)
            if n > last:
                where = truth_at(truth, [m["t_s"]])[0] if truth else None
                out.extend([(t, where)] * (n - last))
            last = n
        return out

    def recoveries(self) -> list[tuple[float, str, Optional[tuple[float, float]]]]:
        """(clock time s, text, where m or None) of each recovery a navigation step ran (the ``recovery`` events
        that start one; a back-up skipped for want of room is not one): where by the simulator's truth, else by the
        fused estimate nearest in time, in the world's frame as the path plot draws it."""
        events = [(float(m["time_s"]), m["text"]) for m in self.rec.topic("/events")
                  if m.get("kind") == "recovery" and ": recovery " in m.get("text", "")]
        if not events:
            return []
        truth = self.rec.topic("/truth")
        if truth:
            return [(t, text, where) for (t, text), where in zip(events, truth_at(truth, [t for t, _ in events]))]
        fused = self.rec.topic("/estimate/fused")
        out: list[tuple[float, str, Optional[tuple[float, float]]]] = []
        for t, text in events:
            near = min(fused, key=lambda m: abs(float(m.get("stamp_s", 0.0)) - t)) if fused else None
            out.append((t, text, self.to_world(near) if near is not None else None))
        return out

    def true_clearance(self) -> tuple[list[float], list[float]]:
        """(times s, gap m) between the footprint and the nearest wall or obstacle, the simulator's truth."""
        pts = [(t, m["clearance_m"]) for t, m in zip(*self.series("/sim/contact")) if m.get("clearance_m") is not None]
        return [t for t, _ in pts], [c for _, c in pts]

    def scan_clearance(self) -> tuple[list[float], list[float]]:
        """(times s, gap m) from each recorded LiDAR scan: its nearest return to the robot's centre (base_link, through
        the profile's mounting) less the footprint radius: the clearance as the robot measured it."""
        raw = self.rec.info.get("lidar_mounting")
        scans = self.rec.topic("/scan")
        if not raw or not scans:
            return [], []
        import numpy as np
        from beastbt.devices.lidar_scan import LidarMounting, base_points_xy
        from beastbt.recording.foxglove import scan_of
        try:
            mounting = LidarMounting(**json.loads(raw))
        except (TypeError, ValueError):
            return [], []
        radius = self.footprint_radius_m()
        times, gaps = [], []
        for t, m in zip(self.times("/scan"), scans):
            pts = base_points_xy(scan_of(m), mounting)
            if len(pts):
                times.append(t)
                gaps.append(float(np.hypot(pts[:, 0], pts[:, 1]).min()) - radius)
        return times, gaps

    def footprint_radius_m(self) -> float:
        """The robot's footprint radius (m): the metadata's, else the recorded profile's (``robot.yaml``), else the
        collision monitor's default."""
        from beastbt.actuation.collision_monitor import DEFAULT_FOOTPRINT_RADIUS_M, footprint_radius
        raw = self.rec.info.get("footprint_radius_m")
        try:
            if raw:
                return float(raw)
        except ValueError:
            pass
        doc = self.attached_yaml("robot.yaml")
        return footprint_radius(doc) if doc is not None else DEFAULT_FOOTPRINT_RADIUS_M

    def to_world(self, p: dict) -> tuple[float, float]:
        """A recorded pose's position in the report's frame (the world's, in the simulator).

        A georeferenced pose goes through its latitude and longitude (the EKF
        anchors its own frame at its first fix, not at the world's datum); an
        odometry-only pose started at the world's start pose.
        """
        x, y = p["x"], p["y"]
        if p.get("lat") is not None and p.get("lon") is not None and p.get("position_valid", True):
            frame = self.local_frame()
            if frame is not None:
                e, n, _ = frame.to_enu(p["lat"], p["lon"])
                return e, n
        if not p.get("position_valid", True) and self.world_start is not None:
            x0, y0, yaw0 = self.world_start
            c, s = math.cos(yaw0), math.sin(yaw0)
            return x0 + c * x - s * y, y0 + s * x + c * y
        return x, y

    def local_frame(self) -> Any:
        """The local ENU frame for GPS and waypoints: the world's datum, else the first fix (as the EKF does)."""
        if not hasattr(self, "_frame"):
            self._frame = self._find_frame()
        return self._frame

    def _find_frame(self) -> Any:
        from beastbt.estimation.geodesy import LocalFrame
        if self.datum is not None:
            return LocalFrame(*self.datum)
        fixes = self.gps_fixes()
        if fixes:
            return LocalFrame(fixes[0][1]["lat"], fixes[0][1]["lon"], fixes[0][1].get("alt_msl") or 0.0)
        for wp in (self.summary or {}).get("waypoints", []):
            if wp.get("lat") is not None:
                return LocalFrame(wp["lat"], wp["lon"])
        return None

    def gps_fixes(self) -> list[tuple[float, dict]]:
        """(time s, message) of the raw GPS fixes with a position, one per epoch (GGA and RMC say it twice)."""
        out: list[tuple[float, dict]] = []
        last_epoch = None
        for t, m in zip(*self.series("/sensors/gps")):
            if not m.get("quality") or m.get("lat") is None or m.get("lon") is None:
                continue  # no fix: nothing to plot
            epoch = m.get("time_utc")
            if epoch is not None and epoch == last_epoch:
                continue
            last_epoch = epoch
            out.append((t, m))
        return out

    # -- the mission ------------------------------------------------------------------------
    def mission(self) -> Any:
        """The recorded mission (for places and tolerances), or None when it no longer loads."""
        text = self.rec.text("mission.yaml")
        if text is None:
            return None
        try:
            from beastbt.mission.model import load_mission
            return load_mission(self.rec.info.get("mission_file") or "mission.yaml", text=text)
        except Exception:
            return None

    def default_tolerance_m(self) -> Optional[float]:
        """The arrival tolerance of a place that gives none: the profile's navigation default (m), if known."""
        try:
            from beastbt.behaviours.navigation import NavConfig
        except ImportError:
            return None
        default = NavConfig().default_tolerance_m
        nav = (self.attached_yaml("robot.yaml") or {}).get("navigation")
        try:
            return float(nav.get("default_tolerance_m", default)) if isinstance(nav, dict) else default
        except (TypeError, ValueError):
            return default

    def waypoints(self) -> list[Waypoint]:
        """The summary's waypoints with their tolerance: the summary's own, else the place's, else the default.

        The fallback is for summaries written before ``tolerance_m`` was
        recorded; it cannot know a tolerance given on the step itself.
        """
        places = self._places()
        default = None
        out = []
        for wp in (self.summary or {}).get("waypoints") or []:
            if "tolerance_m" in wp:
                tol = wp["tolerance_m"]
            else:
                place = places.get(wp.get("name"))
                tol = getattr(place, "tolerance_m", None)
                if tol is None:
                    default = default if default is not None else self.default_tolerance_m()
                    tol = default
            simulated = "truth" in (self.summary or {})
            estimated = wp.get("estimated_error_m", None if simulated else wp.get("arrival_error_m"))
            out.append(Waypoint(str(wp.get("name", "?")), wp.get("lat"), wp.get("lon"), bool(wp.get("reached")),
                                tol, wp.get("arrival_error_m"), wp.get("time_s"), estimated,
                                wp.get("arrival_error_m") if simulated else None, wp.get("x"), wp.get("y")))
        if not any(w.x is not None for w in out):
            # Summaries from before map places joined the waypoints kept them in map_waypoints only.
            for wp in (self.summary or {}).get("map_waypoints") or []:
                reached = bool(wp.get("reached"))
                err = wp.get("arrival_error_m") if reached else None
                out.append(Waypoint(str(wp.get("name", "?")), None, None, reached, wp.get("tolerance_m"), err,
                                    wp.get("time_s"), wp.get("estimated_error_m") if reached else None,
                                    err if simulated else None, wp.get("x"), wp.get("y")))
        return out

    def map_to_world(self) -> Optional[tuple[float, float, float]]:
        """The saved map's frame in the report's (the world's) frame (x m, y m, yaw rad), or None (no saved map,
        or no world start): the robot started at the world's start and at the mission's start on the map."""
        if not hasattr(self, "_map_to_world"):
            self._map_to_world = None
            mission = self.mission()
            if self.world_start is not None and mission is not None and getattr(mission, "map_file", None):
                from beastbt.behaviours.map_navigation import mission_map_start
                from beastbt.estimation.map_localiser import compose, invert
                self._map_to_world = compose(self.world_start, invert(tuple(mission_map_start(mission))))
        return self._map_to_world

    def map_point(self, x: float, y: float) -> Optional[tuple[float, float]]:
        """A point of the saved map's frame (m) in the report's frame, or None when the map is not placed."""
        t = self.map_to_world()
        if t is None:
            return None
        c, s = math.cos(t[2]), math.sin(t[2])
        return t[0] + c * x - s * y, t[1] + s * x + c * y

    def localiser_path(self) -> list[tuple[float, float]]:
        """The localiser's pose on the saved map (``/map/pose``) in the report's frame (m); empty without."""
        if self.map_to_world() is None:
            return []
        out = []
        for m in self.rec.topic("/map/pose"):
            p = m["pose"]["position"]
            out.append(self.map_point(p["x"], p["y"]))
        return out

    def _places(self) -> dict:
        if not hasattr(self, "_place_map"):
            mission = self.mission()
            self._place_map = dict(mission.places) if mission is not None else {}
        return self._place_map

    def targets(self) -> list[tuple[str, float, float, Optional[float], Optional[bool]]]:
        """Where the mission meant to go, in the map's frame: (name, east m, north m, tolerance m, reached).

        The summary's waypoints first (reached True or False), then the
        mission's places no step got to (reached None).
        """
        frame = self.local_frame()
        out = []
        seen = set()
        for wp in self.waypoints():
            if wp.name in seen:
                continue
            if wp.lat is not None and wp.lon is not None and frame is not None:
                e, n, _ = frame.to_enu(wp.lat, wp.lon)
            elif wp.x is not None and wp.y is not None and self.map_point(wp.x, wp.y) is not None:
                e, n = self.map_point(wp.x, wp.y)  # a place on the saved map
            else:
                continue
            seen.add(wp.name)
            out.append((wp.name, e, n, wp.tolerance_m, wp.reached))
        default = None
        for name, place in self._places().items():
            if name in seen:
                continue
            if getattr(place, "lat", None) is not None and frame is not None:
                e, n, _ = frame.to_enu(place.lat, place.lon)
            elif getattr(place, "x", None) is not None and self.map_point(place.x, place.y) is not None:
                e, n = self.map_point(place.x, place.y)
            else:
                continue
            tol = getattr(place, "tolerance_m", None)
            if tol is None:
                default = default if default is not None else self.default_tolerance_m()
                tol = default
            out.append((name, e, n, tol, None))
        return out

    def fences(self) -> list[tuple[str, str, list[tuple[float, float]]]]:
        """The mission's fences in the map's frame: (name, keep ``in``/``out``, corners as (east m, north m))."""
        frame = self.local_frame()
        mission = self.mission()
        if frame is None or mission is None:
            return []
        out = []
        for name, fence in getattr(mission, "fences", {}).items():
            corners = [tuple(frame.to_enu(lat, lon)[:2]) for lat, lon in fence.corners]
            out.append((str(name), fence.keep, corners))
        return out

    # -- what happened ----------------------------------------------------------------------
    def outcome(self) -> str:
        """success / failure / stopped, or why it is unknown."""
        if self.summary:
            return self.summary.get("status", "?")
        ends = [m for m in self.rec.topic("/events") if m["kind"] == "mission_end"]
        if ends:
            return ends[-1]["text"].split(":")[0]
        return "unknown (the run did not finish: no summary)"

    def duration_s(self) -> float:
        """Mission time covered, seconds."""
        if self.summary and "sim_time_s" in self.summary:
            return float(self.summary["sim_time_s"])
        times = self.times("/cmd/gate")
        return times[-1] - times[0] if times else 0.0

    def distance_m(self) -> tuple[float, str]:
        """Distance travelled (m) and where it comes from."""
        if self.summary and "distance_m" in self.summary:
            return float(self.summary["distance_m"]), "summary"
        truth = self.rec.topic("/truth")
        if truth:
            return sum(math.hypot(b["x"] - a["x"], b["y"] - a["y"]) for a, b in zip(truth, truth[1:])), "truth"
        odom = self.rec.topic("/estimate/odom")
        return (odom[-1]["distance_m"] if odom else 0.0), "odometry"


# -- the terminal summary ---------------------------------------------------------------------


def summary_text(d: RunData) -> str:
    """A few lines for a person: outcome, duration, distance, waypoints, failsafes, recording."""
    rec, s = d.rec, d.summary or {}
    info = rec.info
    lines = [f"run {d.name}: mission {d.mission_name()}: {d.outcome().upper()}"]
    ticks = s.get("ticks", len(rec.messages.get("/cmd/gate", [])))
    dist, source = d.distance_m()
    lines.append(f"  duration {d.duration_s():.1f} s ({ticks} ticks), distance {dist:.2f} m"
                 + ("" if source == "summary" else f" ({source})")
                 + (f", top speed {s['max_speed_mps']:.2f} m/s" if "max_speed_mps" in s else ""))
    where = [f"robot {info.get('robot_profile', '?')}"]
    if info.get("world"):
        where.append(f"world {info['world']}")
    where.append(f"seed {info.get('seed', s.get('seed', '?'))}")
    when = d.started_utc()
    if when is not None:
        where.append(f"started {when:%Y-%m-%d %H:%M:%S} UTC")
    lines.append("  " + ", ".join(where))
    if s.get("home") is not None:
        lines.append(home_line(s["home"]))
    wps = d.waypoints()
    if wps:
        lines.append("  waypoints:")
        for wp in wps:
            lines.append("    " + waypoint_text(wp.name, wp.reached, wp.tolerance_m, wp.estimated_error_m,
                                                  wp.true_error_m, wp.time_s)
                         + (f" [map x {wp.x:.2f} m, y {wp.y:.2f} m]" if wp.x is not None and wp.y is not None else ""))
    else:
        lines.append("  waypoints: none")
    obstacles = obstacles_line(s)
    if obstacles:
        lines.append(obstacles)
    lines.extend(vision_lines(s))  # docks, photos, alerts: as beastbt run ended with them
    recoveries = d.recoveries()
    counted = s.get("recoveries")
    if recoveries or counted is not None:
        kinds = (counted or {}).get("kinds") or {}
        lines.append(f"  recoveries: {len(recoveries) if counted is None else counted.get('count', 0)}"
                     + (" (" + ", ".join(f"{k} {n}" for k, n in kinds.items()) + ")" if kinds else ""))
        for t, text, _ in recoveries:
            lines.append(f"    [{t:8.2f} s] {text}")
    failsafes = rec.topic("/failsafes")
    if failsafes:
        lines.append("  failsafes:")
        for t, m in zip(d.times("/failsafes"), failsafes):
            lines.append(f"    [{t:8.2f} s] {m['text']}")
    else:
        lines.append("  failsafes: none")
    r = s.get("recording") or {}
    dropped = r.get("dropped")
    state = "complete" if rec.complete else (f"cut short ({rec.stopped_because}; `beastbt recover RUN` rewrites it "
                                             f"as a whole MCAP file for other tools)")
    lines.append(f"  recording: {rec.message_count()} messages, "
                 + (f"{dropped} dropped" if dropped is not None else "dropped unknown (no summary)")
                 + f", file {state}")
    return "\n".join(lines)


def default_out(run: str) -> Path:
    """``report/`` in the run folder; for a loose ``x.mcap``, ``x_report/`` beside it."""
    path = find_recording(run)
    if path.name == "run.mcap" or Path(run).is_dir():
        return path.parent / "report"
    return path.parent / f"{path.stem}_report"


def make_report(run: str, out: Optional[str] = None) -> Report:
    """Read the run, write the plots and report.html into the report folder, return what was made."""
    d = RunData.load(run)
    folder = Path(out) if out else default_out(run)
    folder.mkdir(parents=True, exist_ok=True)
    report = Report(summary_text(d), folder)
    for stem, _title, fn in PLOTS:
        target = folder / f"{stem}.png"
        why = fn(d, target)
        if why is None:
            report.plots[stem] = target
        else:
            report.skipped[stem] = why
            if target.exists():
                target.unlink()  # a stale plot from an older report would mislead
    report.html = write_html(d, report)
    return report


WAYPOINT_COLUMNS = ("waypoint", "reached", "tolerance (m)", "estimated distance (m)", "true distance (m)",
                    "arrived at (s)")
"""The header of the waypoint table."""
WAYPOINT_NOTE = ("A place counts as reached when the robot's fused estimate comes within the tolerance (the "
                 "estimated distance). The true distance (simulator) is where the robot really stopped: it adds the "
                 "estimate's own error, a few metres with a plain GPS, so it may exceed the tolerance of a place that "
                 "was rightly reached.")
"""What the waypoint table's distances mean, printed above it."""


def waypoint_table(d: RunData) -> list[tuple[str, ...]]:
    """The waypoint table's rows as text, in :data:`WAYPOINT_COLUMNS` order (empty cells for what is unknown)."""
    def num(v: Optional[float]) -> str:
        return "" if v is None else f"{v:.2f}"

    rows = []
    for wp in d.waypoints():
        rows.append((wp.name, "yes" if wp.reached else "NO", num(wp.tolerance_m), num(wp.estimated_error_m),
                     num(wp.true_error_m), "" if wp.time_s is None else f"{wp.time_s:.1f}"))
    return rows


def write_html(d: RunData, report: Report) -> Path:
    """One page with the summary, the waypoint table, the plots, the failsafes and the events."""
    esc = html.escape
    titles = {stem: title for stem, title, _ in PLOTS}
    parts = [
        "<!DOCTYPE html>",
        f"<html><head><meta charset='utf-8'><title>{esc(d.title())}</title>",
        "<style>body{font-family:sans-serif;margin:2em;max-width:1100px}img{max-width:100%;border:1px solid #ccc}"
        "pre{background:#f4f4f4;padding:1em}table{border-collapse:collapse}td,th{border:1px solid #ccc;"
        "padding:2px 8px;text-align:left}td.num{text-align:right}</style></head><body>",
        f"<h1>{esc(d.title())}</h1>",
        f"<p>run {esc(d.name)}</p>",
        f"<pre>{esc(report.text)}</pre>",
    ]
    rows = waypoint_table(d)
    if rows:
        parts.append(f"<h2>Waypoints</h2><p>{esc(WAYPOINT_NOTE)}</p><table><tr>"
                     + "".join(f"<th>{esc(c)}</th>" for c in WAYPOINT_COLUMNS) + "</tr>")
        for row in rows:
            cells = [f"<td>{esc(row[0])}</td>", f"<td>{esc(row[1])}</td>"]
            cells += [f"<td class='num'>{esc(v)}</td>" for v in row[2:]]
            parts.append("<tr>" + "".join(cells) + "</tr>")
        parts.append("</table>")
    for stem, path in report.plots.items():
        parts.append(f"<h2>{esc(titles[stem])}</h2><img src='{esc(path.name)}' alt='{esc(titles[stem])}'>")
    if report.skipped:
        parts.append("<h2>Not plotted</h2><ul>")
        parts.extend(f"<li>{esc(titles[k])}: {esc(v)}</li>" for k, v in report.skipped.items())
        parts.append("</ul>")
    snapshots = [(name, data) for name, data in d.rec.attachments.items() if name.lower().endswith((".jpg", ".jpeg"))]
    if snapshots:
        parts.append("<h2>Snapshots</h2>")
        for name, data in snapshots:
            target = report.folder / f"snapshot_{Path(name).name}"
            target.write_bytes(data)  # from the recording: the page works for a lone .mcap too
            parts.append(f"<figure><img src='{esc(target.name)}' alt='{esc(name)}'><figcaption>{esc(name)}"
                         "</figcaption></figure>")
    events = d.rec.topic("/events")
    if events:
        parts.append(f"<h2>Events ({len(events)})</h2><table><tr><th>time (s)</th><th>kind</th><th>text</th></tr>")
        for t, m in list(zip(d.times("/events"), events))[:500]:
            parts.append(f"<tr><td>{t:.2f}</td><td>{esc(m['kind'])}</td><td>{esc(m['text'])}</td></tr>")
        parts.append("</table>")
    parts.append("</body></html>")
    target = report.folder / "report.html"
    target.write_text("\n".join(parts) + "\n", encoding="utf-8")
    return target


__all__ = ["make_report", "Report", "RunData", "Waypoint", "summary_text", "step_intervals", "StepRun",
           "timeline_rows", "map_extent", "draw_path", "position_errors", "waypoint_table", "WAYPOINT_COLUMNS", "WAYPOINT_NOTE",
           "PLOTS", "FIG_SIZE_IN", "MAP_SIZE_IN", "DPI", "plot_clearance", "plot_path",
           "plot_line_error", "plot_position_error", "plot_saved_map", "plot_speeds", "plot_timeline"]
