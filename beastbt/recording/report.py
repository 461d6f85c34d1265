"""``beastbt report RUN``: a run at a glance, in the terminal and as plots.

From a run folder (``runs/<time>_<mission>/``) or an ``.mcap`` file:

* a terminal summary: outcome, duration, distance, waypoints with their
  arrival errors, failsafes, dropped messages;
* a report folder (``report/`` in the run folder unless ``--out DIR``) with
  PNG plots made with matplotlib (Agg backend, no display needed):
  ``path.png`` (the path on a map in metres: ground truth when simulated, the
  fused estimate, odometry, raw GPS fixes converted to local metres,
  waypoints with their tolerance circles, walls), ``position_error.png``
  (fused and odometry against truth), ``speeds.png`` (commanded against
  actual), ``line_error.png`` (when a line was followed), ``timeline.png``
  (which step ran when), and ``report.html`` showing them together.

A plot whose data the run does not have (no truth on the robot, no GPS, no
line) is left out, and the report says so.
"""

from __future__ import annotations

import html
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, Optional

from beastbt.recording.reader import Recording, find_recording, read_recording

FIG_SIZE_IN = (10.0, 6.0)
"""Size of every plot except the map, inches (at :data:`DPI`: 1000 x 600 pixels)."""
MAP_SIZE_IN = (8.0, 8.0)
"""Size of the map plot, inches (800 x 800 pixels)."""
DPI = 100


NOT_PLOTTED = ("/sensors/imu", "/sensors/battery", "/sensors/joystick", "/sensors/camera", "/camera/image",
               "/pose/fused", "/gps/fix", "/log", "/cmd/servo", "/cmd/mux", "/cmd/teleop", "/devices/state")
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
class RunData:
    """A recording and its summary, with the series the plots need (seconds, metres, world frame)."""

    rec: Recording
    summary: Optional[dict]
    name: str
    world_start: Optional[tuple[float, float, float]] = None
    datum: Optional[tuple[float, float, float]] = None

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
        return data

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

    def series(self, topic: str) -> tuple[list[float], list[dict]]:
        """(times in s, messages) of a topic."""
        return self.rec.times_s(topic), self.rec.topic(topic)

    def local_frame(self) -> Any:
        """The local ENU frame for GPS and waypoints: the world's datum, else the first fix (as the EKF does)."""
        if not hasattr(self, "_frame"):
            self._frame = self._find_frame()
        return self._frame

    def _find_frame(self) -> Any:
        from beastbt.estimation.geodesy import LocalFrame
        if self.datum is not None:
            return LocalFrame(*self.datum)
        fixes = self.rec.topic("/sensors/gps")
        if fixes:
            return LocalFrame(fixes[0]["lat"], fixes[0]["lon"], fixes[0].get("alt_msl") or 0.0)
        for wp in (self.summary or {}).get("waypoints", []):
            if wp.get("lat") is not None:
                return LocalFrame(wp["lat"], wp["lon"])
        return None

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
            import yaml

            from beastbt.behaviours.navigation import NavConfig
        except ImportError:
            return None
        default = NavConfig().default_tolerance_m
        text = self.rec.text("robot.yaml")
        try:
            nav = (yaml.safe_load(text) or {}).get("navigation") or {} if text else {}
            return float(nav.get("default_tolerance_m", default))
        except (yaml.YAMLError, AttributeError, TypeError, ValueError):
            return default

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
        times = self.rec.times_s("/cmd/gate")
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
    mission = info.get("mission") or s.get("mission", "?")
    lines = [f"run {d.name}: mission {mission}: {d.outcome().upper()}"]
    ticks = s.get("ticks", len(rec.messages.get("/cmd/gate", [])))
    dist, source = d.distance_m()
    lines.append(f"  duration {d.duration_s():.1f} s ({ticks} ticks), distance {dist:.2f} m"
                 + ("" if source == "summary" else f" ({source})")
                 + (f", top speed {s['max_speed_mps']:.2f} m/s" if "max_speed_mps" in s else ""))
    where = [f"robot {info.get('robot_profile', '?')}"]
    if info.get("world"):
        where.append(f"world {info['world']}")
    where.append(f"seed {info.get('seed', s.get('seed', '?'))}")
    lines.append("  " + ", ".join(where))
    wps = s.get("waypoints") or []
    if wps:
        lines.append("  waypoints:")
        for wp in wps:
            err = wp.get("arrival_error_m")
            when = wp.get("time_s")
            lines.append(f"    {wp.get('name', '?')}: {'reached' if wp.get('reached') else 'NOT reached'}"
                         + (f", {err:.2f} m off" if err is not None else "")
                         + (f" at {when:.1f} s" if when is not None else ""))
    else:
        lines.append("  waypoints: none")
    failsafes = rec.topic("/failsafes")
    if failsafes:
        lines.append("  failsafes:")
        for m in failsafes:
            lines.append(f"    [{m['time_s']:8.2f} s] {m['text']}")
    else:
        lines.append("  failsafes: none")
    r = s.get("recording") or {}
    dropped = r.get("dropped")
    state = "complete" if rec.complete else f"cut short ({rec.stopped_because})"
    lines.append(f"  recording: {rec.message_count()} messages, "
                 + (f"{dropped} dropped" if dropped is not None else "dropped unknown (no summary)")
                 + f", file {state}")
    return "\n".join(lines)


# -- plots --------------------------------------------------------------------------------------


def _plt() -> Any:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _mark_failsafes(ax: Any, d: RunData) -> None:
    for i, m in enumerate(d.rec.topic("/failsafes")):
        ax.axvline(m["time_s"], color="tab:red", linestyle=":", linewidth=1,
                   label="failsafe" if i == 0 else None)



def _save(plt, fig, out: Path) -> None:
    """Lay out, write ``out`` as PNG at the report's resolution, and free the figure."""
    fig.tight_layout()
    fig.savefig(out, dpi=DPI)
    plt.close(fig)

def plot_path(d: RunData, out: Path) -> Optional[str]:
    """The path on a map in metres; returns why it was skipped, or None."""
    truth = d.rec.topic("/truth")
    fused = d.rec.topic("/estimate/fused")
    odom = d.rec.topic("/estimate/odom")
    gps = d.rec.topic("/sensors/gps")
    if not (truth or fused or odom or gps):
        return "no positions recorded"
    plt = _plt()
    fig, ax = plt.subplots(figsize=MAP_SIZE_IN, dpi=DPI)
    for w in json.loads(d.rec.info.get("world_walls", "[]")):
        ax.plot([w[0], w[2]], [w[1], w[3]], color="0.3", linewidth=3, solid_capstyle="butt")
    frame = d.local_frame()
    if gps and frame is not None:
        pts = [frame.to_enu(m["lat"], m["lon"], m.get("alt_msl"))[:2] for m in gps]
        ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=6, color="tab:orange", alpha=0.6,
                   label=f"GPS fixes ({len(pts)})", zorder=2)
    if truth:
        ax.plot([m["x"] for m in truth], [m["y"] for m in truth], color="black", linewidth=2, label="truth", zorder=3)
    if odom:
        pts = [d.to_world(m) for m in odom]
        ax.plot([p[0] for p in pts], [p[1] for p in pts], color="tab:green", linewidth=1, linestyle="--",
                label="odometry", zorder=4)
    if fused:
        pts = [d.to_world(m) for m in fused]
        ax.plot([p[0] for p in pts], [p[1] for p in pts], color="tab:blue", linewidth=1.2, label="fused estimate",
                zorder=5)
    start = truth[0] if truth else None
    if start is not None:
        ax.plot(start["x"], start["y"], marker="o", color="black", markersize=8, label="start", zorder=6)
    _draw_waypoints(ax, d, frame)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title(f"{d.rec.info.get('mission', d.name)}: path")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    _save(plt, fig, out)
    return None


def _draw_waypoints(ax: Any, d: RunData, frame: Any) -> None:
    """Mission places and summary waypoints, each with its tolerance circle."""
    if frame is None:
        return
    from matplotlib.patches import Circle
    mission = d.mission()
    places = dict(mission.places) if mission is not None else {}
    wps = {wp.get("name"): wp for wp in (d.summary or {}).get("waypoints", []) if wp.get("lat") is not None}
    default_tol = d.default_tolerance_m()
    seen = set()
    for name, wp in list(wps.items()) + [(n, None) for n in places if n not in wps]:
        if name in seen:
            continue
        seen.add(name)
        place = places.get(name)
        lat = wp["lat"] if wp else place.lat
        lon = wp["lon"] if wp else place.lon
        tol = ((wp or {}).get("tolerance_m") or (getattr(place, "tolerance_m", None) if place is not None else None)
               or default_tol)
        e, n, _ = frame.to_enu(lat, lon)
        reached = wp.get("reached") if wp else None
        color = "tab:green" if reached else ("tab:red" if reached is False else "tab:purple")
        ax.plot(e, n, marker="x", color=color, markersize=9, zorder=7)
        if tol:
            ax.add_patch(Circle((e, n), tol, fill=False, color=color, linestyle="--", linewidth=1, zorder=7))
        ax.annotate(str(name), (e, n), textcoords="offset points", xytext=(6, 6), fontsize=8, color=color)


def plot_position_error(d: RunData, out: Path) -> Optional[str]:
    """Distance between the estimates and the truth over time."""
    t_truth, truth = d.series("/truth")
    if not truth:
        return "no ground truth (not a simulated run)"
    t_fused, fused = d.series("/estimate/fused")
    t_odom, odom = d.series("/estimate/odom")
    if not fused and not odom:
        return "no pose estimate recorded"
    by_time = {t: m for t, m in zip(t_truth, truth)}
    plt = _plt()
    fig, ax = plt.subplots(figsize=FIG_SIZE_IN, dpi=DPI)
    for label, times, poses, style in (("fused estimate", t_fused, fused, "-"), ("odometry", t_odom, odom, "--")):
        pts = [(t, d.to_world(p), by_time[t]) for t, p in zip(times, poses) if t in by_time]
        if pts:
            ax.plot([t for t, _, _ in pts], [math.hypot(p[0] - tr["x"], p[1] - tr["y"]) for _, p, tr in pts],
                    style, label=label)
    _mark_failsafes(ax, d)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("position error (m)")
    ax.set_title("position error against ground truth")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    _save(plt, fig, out)
    return None


def plot_speeds(d: RunData, out: Path) -> Optional[str]:
    """Commanded against actual forward speed and turn rate."""
    t_gate, gate = d.series("/cmd/gate")
    if not gate:
        return "no commands recorded"
    t_mission, mission = d.series("/cmd/mission")
    t_truth, truth = d.series("/truth")
    t_odo, odo = d.series("/sensors/odometry")
    t_fused, fused = d.series("/estimate/fused")
    plt = _plt()
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=FIG_SIZE_IN, dpi=DPI, sharex=True)
    if mission:
        ax1.plot(t_mission, [m["linear_mps"] for m in mission], color="tab:gray", linewidth=1, label="mission command")
    ax1.plot(t_gate, [m["linear_mps"] for m in gate], color="tab:blue", linewidth=1.5, label="sent (after gate)")
    if truth:
        ax1.plot(t_truth, [m["v_mps"] for m in truth], color="black", linewidth=1, label="true speed")
    if odo:
        ax1.plot(t_odo, [(m["left_mps"] + m["right_mps"]) / 2 for m in odo], color="tab:green", linewidth=1,
                 linestyle="--", label="wheel odometry")
    elif fused:
        ax1.plot(t_fused, [m["speed_mps"] for m in fused], color="tab:green", linewidth=1, linestyle="--",
                 label="fused estimate")
    ax1.set_ylabel("forward speed (m/s)")
    ax1.legend(loc="best", fontsize=8)
    ax1.grid(True, alpha=0.3)
    if mission:
        ax2.plot(t_mission, [m["angular_rps"] for m in mission], color="tab:gray", linewidth=1, label="mission command")
    ax2.plot(t_gate, [m["angular_rps"] for m in gate], color="tab:blue", linewidth=1.5, label="sent (after gate)")
    if truth:
        ax2.plot(t_truth, [m["w_rps"] for m in truth], color="black", linewidth=1, label="true turn rate")
    if fused:
        ax2.plot(t_fused, [m["yaw_rate_rps"] for m in fused], color="tab:green", linewidth=1, linestyle="--",
                 label="fused estimate")
    for ax in (ax1, ax2):
        _mark_failsafes(ax, d)
    ax2.set_ylabel("turn rate (rad/s)")
    ax2.set_xlabel("time (s)")
    ax2.legend(loc="best", fontsize=8)
    ax2.grid(True, alpha=0.3)
    fig.suptitle("commanded against actual")
    _save(plt, fig, out)
    return None


def plot_line_error(d: RunData, out: Path) -> Optional[str]:
    """The line's lateral offset and angle as the detector saw them."""
    t, obs = d.series("/sensors/line")
    if not obs:
        return "no line observations (no line was followed)"
    plt = _plt()
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=FIG_SIZE_IN, dpi=DPI, sharex=True)
    seen = [(ti, m) for ti, m in zip(t, obs) if m["seen"]]
    lost = [ti for ti, m in zip(t, obs) if not m["seen"]]
    dot = 2 if len(obs) > 300 else 5  # a short run still shows its few points
    ax1.plot([ti for ti, _ in seen], [m["offset_m"] * 100 for _, m in seen], ".", markersize=dot, color="tab:blue",
             label="offset of the line (cm, + left)")
    if lost:
        ax1.plot(lost, [0.0] * len(lost), "|", color="tab:red", label="line not seen")
    ax1.axhline(5, color="0.5", linestyle=":", linewidth=1)
    ax1.axhline(-5, color="0.5", linestyle=":", linewidth=1, label="+/- 5 cm")
    ax1.set_ylabel("line offset (cm)")
    ax1.legend(loc="best", fontsize=8)
    ax1.grid(True, alpha=0.3)
    ax2.plot([ti for ti, _ in seen], [math.degrees(m["angle_rad"]) for _, m in seen], ".", markersize=dot,
             color="tab:purple", label="line angle (deg)")
    ax2.plot(t, [m["confidence"] * 10 for m in obs], color="0.6", linewidth=0.8, label="confidence x 10")
    ax2.set_ylabel("angle (deg)")
    ax2.set_xlabel("time (s)")
    ax2.legend(loc="best", fontsize=8)
    ax2.grid(True, alpha=0.3)
    fig.suptitle("line error as detected")
    _save(plt, fig, out)
    return None


class StepRun(NamedTuple):
    """One run of a leaf step: ``name``, ``start_s`` and ``end_s`` (s), how it ended (``how``: SUCCESS,
    FAILURE, INVALID when interrupted, RUNNING when the recording ends first) and the node's stable ``node_id``
    (None in a recording made before the ids: steps are then told apart by name only)."""

    name: str
    start_s: float
    end_s: float
    how: str
    node_id: Optional[str] = None

    @property
    def key(self) -> str:
        """What tells this step apart from the others: its node id, else (an old recording) its name."""
        return self.node_id if self.node_id is not None else self.name


def _composites(nodes: list[dict]) -> set[str]:
    """The keys (ids, or names in a recording made before the ids) of the recorded tree's inner nodes."""
    if any("id" in n for n in nodes):
        return {n["parent"] for n in nodes if n.get("parent") is not None}
    # Before the ids: by name, and a name that is a leaf somewhere counts as a step.
    return {n["name"] for n in nodes if not n.get("leaf")} - {n["name"] for n in nodes if n.get("leaf")}


def step_intervals(d: RunData) -> list[StepRun]:
    """Every run of a leaf step, from the /tree channel, in the order they ended.

    Steps are the tree's leaves (composites, repeats and tasks are left
    out); a node the recorded tree did not list (a return_home put in by a
    failsafe) counts as a step. Two steps that share a name are two steps.
    """
    composites = _composites(json.loads(d.rec.info.get("tree", "[]")))
    dt = 1.0 / float(d.rec.info.get("rate_hz", "20") or 20)
    open_at: dict[str, tuple[str, float, Optional[str]]] = {}
    out: list[StepRun] = []
    end_t = 0.0
    for m in d.rec.topic("/tree"):
        t = m["now_s"]
        end_t = t
        for c in m["changes"]:
            name, status, node_id = c["name"], c["status"], c.get("id")
            key = node_id if node_id is not None else name
            if key in composites:
                continue
            if status == "RUNNING":
                open_at.setdefault(key, (name, t, node_id))
            elif key in open_at:
                _, start, _ = open_at.pop(key)
                out.append(StepRun(name, start, max(t, start + dt), status, node_id))
            elif status != "INVALID":
                # Done within one tick (never seen RUNNING). A reset to INVALID of a step that was not
                # running (a repeat starting over) is not a run of it.
                out.append(StepRun(name, t, t + dt, status, node_id))
    gates = d.rec.times_s("/cmd/gate")
    end_t = max(end_t, gates[-1] if gates else end_t)
    for name, start, node_id in open_at.values():
        out.append(StepRun(name, start, max(end_t, start + dt), "RUNNING", node_id))
    return out


def timeline_rows(intervals: list[StepRun]) -> list[tuple[str, str]]:
    """(key, label) of the timeline's rows, in the order the steps first started: one row per step.

    A label is the step's name, with its node id when another step shares that name.
    """
    keys: dict[str, str] = {}
    for iv in sorted(intervals, key=lambda iv: iv.start_s):
        keys.setdefault(iv.key, iv.name)
    names = [name for name in keys.values()]
    return [(key, name if names.count(name) == 1 or key == name else f"{name} [{key}]") for key, name in keys.items()]


def plot_timeline(d: RunData, out: Path) -> Optional[str]:
    """Which step ran when: one row per step, a bar per run of it, coloured by how it ended."""
    intervals = step_intervals(d)
    if not intervals:
        return "no tree changes recorded"
    order = timeline_rows(intervals)
    rows = {key: i for i, (key, _) in enumerate(order)}
    colors = {"SUCCESS": "tab:green", "FAILURE": "tab:red", "INVALID": "tab:gray", "RUNNING": "tab:blue"}
    plt = _plt()
    fig, ax = plt.subplots(figsize=FIG_SIZE_IN, dpi=DPI)
    span = max(iv.end_s for iv in intervals) - min(iv.start_s for iv in intervals)
    min_width = span * 0.004  # a step done in one tick still shows
    for iv in intervals:
        ax.barh(rows[iv.key], max(iv.end_s - iv.start_s, min_width), left=iv.start_s, height=0.6,
                color=colors.get(iv.how, "tab:blue"), edgecolor="black", linewidth=0.3)
    _mark_failsafes(ax, d)
    ax.set_yticks(range(len(order)))
    ax.set_yticklabels([label for _, label in order], fontsize=8 if len(order) < 25 else 6)
    ax.invert_yaxis()
    ax.set_xlabel("time (s)")
    ax.set_title("which step ran when (green: succeeded, red: failed, grey: interrupted, blue: still running)")
    ax.grid(True, axis="x", alpha=0.3)
    _save(plt, fig, out)
    return None


PLOTS = (
    ("path", "path on a map", plot_path),
    ("position_error", "position error over time", plot_position_error),
    ("speeds", "commanded against actual speeds", plot_speeds),
    ("line_error", "line error over time", plot_line_error),
    ("timeline", "which step ran when", plot_timeline),
)
"""(file stem, title, function(data, png path) -> reason skipped or None)."""


# -- the report -------------------------------------------------------------------------------------


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


def write_html(d: RunData, report: Report) -> Path:
    """One page with the summary, the plots, the failsafes and the events."""
    esc = html.escape
    titles = {stem: title for stem, title, _ in PLOTS}
    parts = [
        "<!DOCTYPE html>",
        f"<html><head><meta charset='utf-8'><title>beastbt run {esc(d.name)}</title>",
        "<style>body{font-family:sans-serif;margin:2em;max-width:1100px}img{max-width:100%;border:1px solid #ccc}"
        "pre{background:#f4f4f4;padding:1em}table{border-collapse:collapse}td,th{border:1px solid #ccc;"
        "padding:2px 8px;text-align:left}</style></head><body>",
        f"<h1>Run {esc(d.name)}</h1>",
        f"<pre>{esc(report.text)}</pre>",
    ]
    wps = (d.summary or {}).get("waypoints") or []
    if wps:
        parts.append("<h2>Waypoints</h2><table><tr><th>name</th><th>reached</th><th>arrival error (m)</th>"
                     "<th>time (s)</th></tr>")
        for wp in wps:
            err = wp.get("arrival_error_m")
            parts.append(f"<tr><td>{esc(str(wp.get('name')))}</td><td>{'yes' if wp.get('reached') else 'no'}</td>"
                         f"<td>{'' if err is None else f'{err:.2f}'}</td><td>{wp.get('time_s', '')}</td></tr>")
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
        for m in events[:500]:
            parts.append(f"<tr><td>{m['time_s']:.2f}</td><td>{esc(m['kind'])}</td><td>{esc(m['text'])}</td></tr>")
        parts.append("</table>")
    parts.append("</body></html>")
    target = report.folder / "report.html"
    target.write_text("\n".join(parts) + "\n", encoding="utf-8")
    return target


__all__ = ["make_report", "Report", "RunData", "summary_text", "step_intervals", "StepRun", "timeline_rows", "PLOTS", "FIG_SIZE_IN",
           "MAP_SIZE_IN", "DPI"]
