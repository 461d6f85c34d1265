"""The report's plots (``beastbt report``): the path on a map, clearance, position error, speeds, line error,
the steps' timeline and the saved map, each a PNG drawn with matplotlib's Agg backend from a
:class:`~beastbt.recording.report.RunData`. A plot whose data the run does not have returns None.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, NamedTuple, Optional

if TYPE_CHECKING:
    from beastbt.recording.report import RunData

GPS_COLOUR = "#f2b277"
"""Raw GPS fixes: a light orange, behind the lines that matter (truth, estimate)."""
FIG_SIZE_IN = (10.0, 6.0)
"""Size of every plot except the map, inches (at :data:`DPI`: 1000 x 600 pixels)."""
MAP_SIZE_IN = (8.0, 8.0)
"""Size of the map plot, inches (800 x 800 pixels)."""
DPI = 100



def _plt() -> Any:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _mark_failsafes(ax: Any, d: RunData) -> None:
    for i, t in enumerate(d.times("/failsafes")):
        ax.axvline(t, color="tab:red", linestyle=":", linewidth=1, label="failsafe" if i == 0 else None)


def _save(plt, fig, out: Path) -> None:
    """Lay out, write ``out`` as PNG at the report's resolution, and free the figure."""
    fig.tight_layout()
    fig.savefig(out, dpi=DPI)
    plt.close(fig)


MAP_MARGIN_M = 1.0
"""Least room left around what the map must show, m (also 5 % of its span): indoors, the nearby walls."""


def map_extent(d: RunData) -> Optional[tuple[float, float, float, float]]:
    """The map's (x min, x max, y min, y max) in metres, square: what the robot did and where it was to go.

    It spans the true path (on a robot without truth: the localiser's pose on
    a saved map, else the fused estimate, else odometry, else the GPS fixes), the line track, and the mission's
    places with their tolerance circles. GPS scatter and walls do not
    widen it: a wild fix or a long building would shrink the path to a dot.
    """
    xs: list[float] = []
    ys: list[float] = []
    truth = d.rec.topic("/truth")
    if truth:
        xs += [m["x"] for m in truth]
        ys += [m["y"] for m in truth]
    elif d.localiser_path():
        xs += [p[0] for p in d.localiser_path()]
        ys += [p[1] for p in d.localiser_path()]
    else:
        for topic in ("/estimate/fused", "/estimate/odom"):
            pts = [d.to_world(m) for m in d.rec.topic(topic)]
            if pts:
                xs += [p[0] for p in pts]
                ys += [p[1] for p in pts]
                break
    for line in d.track():
        xs += [p[0] for p in line]
        ys += [p[1] for p in line]
    for _, e, n, tol, _ in d.targets():
        r = tol or 0.0
        xs += [e - r, e + r]
        ys += [n - r, n + r]
    for _, _, corners in d.fences():
        xs += [p[0] for p in corners]
        ys += [p[1] for p in corners]
    if not xs:
        frame = d.local_frame()
        for _, m in d.gps_fixes() if frame is not None else []:
            e, n, _ = frame.to_enu(m["lat"], m["lon"])
            xs.append(e)
            ys.append(n)
    if not xs:
        return None
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    half = max(x1 - x0, y1 - y0) / 2.0
    half += max(MAP_MARGIN_M, 0.05 * 2.0 * half)
    cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
    return cx - half, cx + half, cy - half, cy + half


def draw_path(d: RunData, ax: Any) -> list[str]:
    """Draw the map on ``ax``; return the labels of what it drew (for the legend and for tests).

    Walls and the line track under everything; the raw GPS fixes, when the
    run had any, light and small; the truth, then odometry and the fused
    estimate over it; where the robot started and ended, collided and ran a
    recovery; the mission's places with their tolerance circles.
    The axis limits are :func:`map_extent`'s.
    """
    truth = d.rec.topic("/truth")
    fused = d.rec.topic("/estimate/fused")
    odom = d.rec.topic("/estimate/odom")
    for i, (x1, y1, x2, y2) in enumerate(d.walls()):
        ax.plot([x1, x2], [y1, y2], color="0.3", linewidth=3, solid_capstyle="butt", zorder=1,
                label="walls" if i == 0 else None)
    for i, line in enumerate(d.track()):
        ax.plot([p[0] for p in line], [p[1] for p in line], color="0.55", linewidth=4, alpha=0.5,
                solid_capstyle="round", zorder=1, label="line track" if i == 0 else None)
    _draw_obstacles(ax, d)
    _draw_fences(ax, d)
    frame = d.local_frame()
    fixes = d.gps_fixes() if frame is not None else []
    if fixes:
        pts = [frame.to_enu(m["lat"], m["lon"])[:2] for _, m in fixes]
        ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=5, color=GPS_COLOUR, edgecolors="none",
                   label=f"GPS fixes ({len(pts)})", zorder=2)
    if odom:
        pts = [d.to_world(m) for m in odom]
        ax.plot([p[0] for p in pts], [p[1] for p in pts], color="tab:green", linewidth=1, linestyle="--",
                label="odometry", zorder=4)
    localiser = d.localiser_path()
    if localiser:
        # On a saved map the robot navigates by the localiser's pose (the fused one is the wheels' and the gyro's
        # there, with no GPS indoors): draw what it went by.
        ax.plot([p[0] for p in localiser], [p[1] for p in localiser], color="tab:blue", linewidth=1.2,
                label="localiser (map pose)", zorder=5)
    elif fused:
        pts = [d.to_world(m) for m in fused]
        ax.plot([p[0] for p in pts], [p[1] for p in pts], color="tab:blue", linewidth=1.2, label="fused estimate",
                zorder=5)
    if truth:
        # Under the estimates, wider: where they agree with it, they show on top of it.
        ax.plot([m["x"] for m in truth], [m["y"] for m in truth], color="black", linewidth=2.5, label="truth",
                zorder=3)
        ax.plot(truth[0]["x"], truth[0]["y"], marker="o", color="tab:green", markeredgecolor="black", markersize=9,
                linestyle="none", label="start", zorder=7)
        ax.plot(truth[-1]["x"], truth[-1]["y"], marker="s", color="tab:red", markeredgecolor="black", markersize=8,
                linestyle="none", label="end", zorder=7)
    hits = [where for _, where in d.collisions() if where is not None]
    if hits:
        ax.plot([p[0] for p in hits], [p[1] for p in hits], marker="X", color="red", markeredgecolor="black",
                markersize=12, linestyle="none", label=f"collision ({len(hits)})", zorder=9)
    turns = [where for _, _, where in d.recoveries() if where is not None]
    if turns:  # where a navigation step ran a recovery (clear, back up, spin, wait) before trying again
        ax.plot([p[0] for p in turns], [p[1] for p in turns], marker="D", color="tab:orange", markeredgecolor="black",
                markersize=8, linestyle="none", label=f"recovery ({len(turns)})", zorder=8)
    _draw_targets(ax, d)
    extent = map_extent(d)
    if extent is not None:
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
    ax.set_aspect("equal", adjustable="box")
    return [h.get_label() for h in ax.get_legend_handles_labels()[0]]


OBSTACLE_COLOUR = "0.45"
PERSON_COLOUR = "tab:purple"


def _draw_obstacles(ax: Any, d: RunData) -> None:
    """Boxes and cylinders filled grey; each person's path dotted and where it really walked (``/sim/contact``)."""
    from matplotlib.patches import Circle, Polygon
    labelled: set[str] = set()

    def label(name: str) -> Optional[str]:
        if name in labelled:
            return None
        labelled.add(name)
        return name

    for o in d.obstacles():
        if o["shape"] == "box":
            ax.add_patch(Polygon(o["corners"], closed=True, facecolor=OBSTACLE_COLOUR, edgecolor="black",
                                 alpha=0.6, zorder=2, label=label("obstacles")))
        elif o["shape"] == "cylinder":
            ax.add_patch(Circle(tuple(o["xy"]), o["radius_m"], facecolor=OBSTACLE_COLOUR, edgecolor="black",
                                alpha=0.6, zorder=2, label=label("obstacles")))
        elif len(o["path"]) > 1:
            ax.plot([p[0] for p in o["path"]], [p[1] for p in o["path"]], color=PERSON_COLOUR, linestyle=":",
                    linewidth=1.5, zorder=2, label=label("person's path"))
    for walk in d.person_walks():
        if len(walk) > 1:
            ax.plot([p[0] for p in walk], [p[1] for p in walk], color=PERSON_COLOUR, linewidth=1.2, alpha=0.7,
                    zorder=2, label=label("person walked"))
    radii = [o["radius_m"] for o in d.obstacles() if o["shape"] == "person"]
    for walk, radius in zip(d.person_walks(), radii):
        if walk:  # the person as big as it is, where the run left it
            ax.add_patch(Circle(walk[-1], radius, facecolor=PERSON_COLOUR, edgecolor="black", alpha=0.5, zorder=6,
                                label=label("person at the end")))


def _draw_fences(ax: Any, d: RunData) -> None:
    """The mission's fences as closed polygons: keep-in green (dashed edge), keep-out red (shaded)."""
    from matplotlib.colors import to_rgba
    from matplotlib.patches import Polygon
    for name, keep, corners in d.fences():
        inside = keep == "in"
        colour = "tab:green" if inside else "tab:red"
        ax.add_patch(Polygon(corners, closed=True, facecolor=to_rgba(colour, 0.0 if inside else 0.15),
                             edgecolor=colour, linestyle="--" if inside else "-", linewidth=1.5, zorder=2,
                             label=f"fence {name} (keep {keep})"))
        x, y = corners[0]
        ax.annotate(f"fence {name}", (x, y), textcoords="offset points", xytext=(4, -10), fontsize=8, color=colour,
                    zorder=8)


def _draw_targets(ax: Any, d: RunData) -> None:
    """The mission's places, each with its tolerance circle: green reached, red missed, purple not tried."""
    from matplotlib.patches import Circle
    for name, e, n, tol, reached in d.targets():
        color = "tab:green" if reached else ("tab:red" if reached is False else "tab:purple")
        ax.plot(e, n, marker="x", color=color, markersize=9, zorder=8)
        if tol:
            ax.add_patch(Circle((e, n), tol, fill=False, color=color, linestyle="--", linewidth=1, zorder=8))
        ax.annotate(str(name), (e, n), textcoords="offset points", xytext=(6, 6), fontsize=9, color=color, zorder=8)


def plot_path(d: RunData, out: Path) -> Optional[str]:
    """The path on a map in metres; returns why it was skipped, or None."""
    if not (d.rec.topic("/truth") or d.rec.topic("/estimate/fused") or d.rec.topic("/estimate/odom")
            or d.gps_fixes()):
        return "no positions recorded"
    plt = _plt()
    fig, ax = plt.subplots(figsize=MAP_SIZE_IN, dpi=DPI)
    draw_path(d, ax)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title(f"{d.title()}: path")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    _save(plt, fig, out)
    return None


def plot_clearance(d: RunData, out: Path) -> Optional[str]:
    """The gap between the footprint and the nearest thing over time: the simulator's truth, the LiDAR's nearest
    return (less the footprint radius), the collisions and the collision monitor's actions marked."""
    t_true, true = d.true_clearance()
    t_scan, scan = d.scan_clearance()
    if not true and not scan:
        return "no clearance recorded (no simulator contact truth, no LiDAR scans)"
    plt = _plt()
    fig, ax = plt.subplots(figsize=FIG_SIZE_IN, dpi=DPI)
    if scan:
        ax.plot(t_scan, scan, color="tab:red", linewidth=0.8, marker=".", markersize=2, alpha=0.8,
                label="LiDAR: nearest return less the footprint", zorder=2)
    if true:
        least = round(min(true), 2) + 0.0  # + 0.0: a touch reads 0.00, not -0.00
        ax.plot(t_true, true, color="black", linewidth=1.5, label=f"truth (least {least:.2f} m)", zorder=3)
    for i, (t, _) in enumerate(d.collisions()):
        ax.axvline(t, color="red", linewidth=2, label="collision" if i == 0 else None, zorder=4)
    acted = [t for t, m in zip(*d.series("/events")) if m.get("kind") == "collision_monitor"
             and any(w in m.get("text", "") for w in (": stop", ": slow", ": approach"))]
    if acted:
        ax.plot(acted, [0.0] * len(acted), marker="^", color="tab:orange", markersize=9, linestyle="none",
                label="collision monitor acted", zorder=5, clip_on=False)
    ax.axhline(0.0, color="0.3", linewidth=1)
    _mark_failsafes(ax, d)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("clearance (m)")
    top = max(true + scan)
    ax.set_ylim(min(-0.05, min(true + scan)), min(top, 5.0) + 0.1)  # far returns outdoors do not flatten the rest
    ax.set_title(f"{d.title()}: clearance to the nearest wall or obstacle")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    _save(plt, fig, out)
    return None


def truth_at(truth: list[dict], stamps: list[float]) -> list[tuple[float, float]]:
    """The true position (m) at each clock time in ``stamps`` (s), interpolated between truth samples."""
    import numpy as np
    t = np.array([m["t_s"] for m in truth])
    x = np.interp(stamps, t, [m["x"] for m in truth])
    y = np.interp(stamps, t, [m["y"] for m in truth])
    return list(zip(x.tolist(), y.tolist()))


def position_errors(d: RunData) -> dict[str, tuple[list[float], list[float]]]:
    """Label -> (times s, distances to the truth m) of the fused estimate, odometry, the raw GPS fixes and, on a
    saved map, the localiser's pose (``/map/pose`` moved onto the world by the summary's ``truth.map_from_world``).

    Estimates are compared with the truth of their own tick; a GPS fix with
    the truth at the moment it was measured (its ``stamp_s``), one per epoch.
    """
    truth = d.rec.messages.get("/truth", [])
    if not truth:
        return {}
    by_time = {t: m for t, m in truth}
    t0 = d.t0_ns
    out: dict[str, tuple[list[float], list[float]]] = {}
    for label, topic in (("fused estimate", "/estimate/fused"), ("odometry", "/estimate/odom")):
        pts = [((t - t0) * 1e-9, d.to_world(p), by_time[t]) for t, p in d.rec.messages.get(topic, []) if t in by_time]
        if pts:
            out[label] = ([t for t, _, _ in pts], [math.hypot(p[0] - tr["x"], p[1] - tr["y"]) for _, p, tr in pts])
    aligned = ((d.summary or {}).get("truth") or {}).get("map_from_world")
    on_map = d.rec.messages.get("/map/pose", [])
    if aligned is not None and on_map:
        # the localiser's pose on the saved map, moved onto the world by the starts (truth.map_from_world)
        from beastbt.estimation.map_localiser import compose, invert
        world_from_map = invert(tuple(aligned))
        import numpy as np
        log_ns = np.array([t for t, _ in truth], dtype=float)
        at = np.array([t for t, _ in on_map], dtype=float)  # both stamped with their tick's log time
        true = zip(np.interp(at, log_ns, [m["x"] for _, m in truth]).tolist(),
                   np.interp(at, log_ns, [m["y"] for _, m in truth]).tolist())
        errs = []
        for (_, m), (tx, ty) in zip(on_map, true):
            x, y, _ = compose(world_from_map, (m["pose"]["position"]["x"], m["pose"]["position"]["y"], 0.0))
            errs.append(math.hypot(x - tx, y - ty))
        out["localiser on the map"] = ([(t - t0) * 1e-9 for t, _ in on_map], errs)
    frame = d.local_frame()
    fixes = d.gps_fixes() if frame is not None and d.datum is not None else []
    if fixes:
        true = truth_at([m for _, m in truth], [m["stamp_s"] for _, m in fixes])
        errs = []
        for (_, m), (tx, ty) in zip(fixes, true):
            e, n, _ = frame.to_enu(m["lat"], m["lon"])
            errs.append(math.hypot(e - tx, n - ty))
        out["raw GPS fix"] = ([t for t, _ in fixes], errs)
    return out


def plot_position_error(d: RunData, out: Path) -> Optional[str]:
    """Distance between the estimates (and the raw GPS fixes) and the truth over time."""
    if not d.rec.topic("/truth"):
        return "no ground truth (not a simulated run)"
    errors = position_errors(d)
    if not errors:
        return "no pose estimate recorded"
    styles = {"raw GPS fix": dict(color=GPS_COLOUR, linewidth=0.8, marker=".", markersize=3, zorder=1),
              "fused estimate": dict(color="tab:blue", linewidth=1.3, zorder=3),
              "odometry": dict(color="tab:green", linewidth=1, linestyle="--", zorder=2),
              "localiser on the map": dict(color="tab:purple", linewidth=1.3, zorder=4)}
    plt = _plt()
    fig, ax = plt.subplots(figsize=FIG_SIZE_IN, dpi=DPI)
    for label in ("raw GPS fix", "odometry", "fused estimate", "localiser on the map"):
        if label in errors:
            times, errs = errors[label]
            rms = math.sqrt(sum(e * e for e in errs) / len(errs))
            size = f"{rms:.2f} m" if rms >= 0.1 else f"{rms:.3f} m"  # the axis's unit; indoors odometry errs by mm
            ax.plot(times, errs, label=f"{label} (RMS {size})", **styles[label])
    _mark_failsafes(ax, d)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance to the truth (m)")
    ax.set_ylim(bottom=0.0)
    ax.set_title(f"{d.title()}: position error against ground truth")
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
    deg = math.degrees(1.0)  # turn rates in deg/s, the unit missions write them in
    # What was measured goes underneath, thin and light (it is noisy); what was asked on top, so that it shows.
    measured = dict(linewidth=0.8, alpha=0.6, zorder=2)
    if truth:
        ax1.plot(t_truth, [m["v_mps"] for m in truth], color="black", label="true speed", **measured)
    if odo:
        ax1.plot(t_odo, [(m["left_mps"] + m["right_mps"]) / 2 for m in odo], color="tab:green", linestyle="--",
                 label="wheel odometry", **measured)
    elif fused:
        ax1.plot(t_fused, [m["speed_mps"] for m in fused], color="tab:green", linestyle="--", label="fused estimate",
                 **measured)
    ax1.plot(t_gate, [m["linear_mps"] for m in gate], color="tab:blue", linewidth=1.5, zorder=3,
             label="sent (after gate)")
    if mission:
        ax1.plot(t_mission, [m["linear_mps"] for m in mission], color="tab:orange", linewidth=1.8, linestyle="--",
                 zorder=4, label="mission command")
    ax1.set_ylabel("forward speed (m/s)")
    ax1.legend(loc="best", fontsize=8)
    ax1.grid(True, alpha=0.3)
    if truth:
        ax2.plot(t_truth, [m["w_rps"] * deg for m in truth], color="black", label="true turn rate", **measured)
    if fused:
        ax2.plot(t_fused, [m["yaw_rate_rps"] * deg for m in fused], color="tab:green", linestyle="--",
                 label="fused estimate", **measured)
    ax2.plot(t_gate, [m["angular_rps"] * deg for m in gate], color="tab:blue", linewidth=1.5, zorder=3,
             label="sent (after gate)")
    if mission:
        ax2.plot(t_mission, [m["angular_rps"] * deg for m in mission], color="tab:orange", linewidth=1.8,
                 linestyle="--", zorder=4, label="mission command")
    for ax in (ax1, ax2):
        _mark_failsafes(ax, d)
    ax2.set_ylabel("turn rate (deg/s)")
    ax2.set_xlabel("time (s)")
    ax2.legend(loc="best", fontsize=8)
    ax2.grid(True, alpha=0.3)
    fig.suptitle(f"{d.title()}: commanded against actual")
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
    fig.suptitle(f"{d.title()}: line error as detected")
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
    out). A node the recorded tree did not list (a return_home put in by a
    failsafe) counts as a step unless its id shows it has children ("1" of
    "1.0"); in a recording from before the ids, unless its name is a
    composite's. Two steps that share a name are two steps.
    """
    composites = _composites(json.loads(d.rec.info.get("tree", "[]")))
    for m in d.rec.topic("/tree"):
        for c in m["changes"]:
            parts = c.get("id", "").split(".")
            composites.update(".".join(parts[:i]) for i in range(1, len(parts)))
    dt = 1.0 / float(d.rec.info.get("rate_hz", "20") or 20)
    open_at: dict[str, tuple[str, float, Optional[str]]] = {}
    out: list[StepRun] = []
    end_t = 0.0
    for t, m in zip(*d.series("/tree")):
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
    gates = d.times("/cmd/gate")
    end_t = max(end_t, gates[-1] if gates else end_t)
    for name, start, node_id in open_at.values():
        out.append(StepRun(name, start, max(end_t, start + dt), "RUNNING", node_id))
    return out


def timeline_rows(intervals: list[StepRun]) -> list[tuple[str, str]]:
    """(key, label) of the timeline's rows, in the order the steps first started: one row per step.

    A label is the step's name; when another step shares that name, also which of them it is in the order they
    first ran ("drive 3 m (2nd)").
    """
    keys: dict[str, str] = {}
    for iv in sorted(intervals, key=lambda iv: iv.start_s):
        keys.setdefault(iv.key, iv.name)
    names = list(keys.values())
    out = []
    for key, name in keys.items():
        if names.count(name) == 1 or key == name:
            out.append((key, name))
            continue
        # Two steps say the same (the two drives of a patrol's lap): told apart in words, by the order in which
        # they first ran, not by their node ids.
        k = sum(1 for other_key, other in out if other == name or other.startswith(f"{name} ("))
        out.append((key, f"{name} ({_ordinal(k + 1)})"))
    return out


def _ordinal(n: int) -> str:
    """1st, 2nd, 3rd, 4th... 11th, 12th, 13th, 21st."""
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


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
    ax.set_title(f"{d.title()}: which step ran when\n(green: succeeded, red: failed, grey: interrupted, "
                 "blue: still running)", fontsize=10)
    ax.grid(True, axis="x", alpha=0.3)
    _save(plt, fig, out)
    return None


def plot_saved_map(d: RunData, out: Path) -> Optional[str]:
    """The mission's saved map (``/map``) with the paths planned on it (``/path``) and the path driven (``/map/pose``,
    the localiser's pose); returns why it was skipped, or None."""
    from beastbt.recording.map_views import draw_map, grid_of_message
    maps = d.rec.topic("/map")
    if not maps:
        return "no saved map in this run (a mission without map:)"
    grid = grid_of_message(maps[-1])
    driven = [(m["pose"]["position"]["x"], m["pose"]["position"]["y"]) for m in d.rec.topic("/map/pose")]
    plt = _plt()
    fig, ax = plt.subplots(figsize=MAP_SIZE_IN, dpi=DPI)
    first = True
    for msg in d.rec.topic("/path"):
        for entity in msg.get("entities") or []:
            for line in entity.get("lines") or []:
                pts = [(p["x"], p["y"]) for p in line["points"]]
                if len(pts) > 1:
                    xs, ys = zip(*pts)
                    ax.plot(xs, ys, "-", color="#2f6fff", lw=0.8, alpha=0.35,
                            label="paths planned" if first else None, zorder=2)
                    first = False
    places = []
    for w in (d.summary or {}).get("map_waypoints") or []:
        if w.get("x") is not None:
            places.append(SimpleNamespace(name=w["name"], x=w["x"], y=w["y"], tolerance_m=w.get("tolerance_m")))
    draw_map(ax, grid, places=places, driven=driven or None, start=(0.0, 0.0, 0.0) if driven else None)
    ax.set_title(f"{d.title()}: on the map")
    _save(plt, fig, out)
    return None


PLOTS = (
    ("path", "path on a map", plot_path),
    ("saved_map", "the saved map with the paths planned and driven", plot_saved_map),
    ("clearance", "clearance to obstacles over time", plot_clearance),
    ("position_error", "position error over time", plot_position_error),
    ("speeds", "commanded against actual speeds", plot_speeds),
    ("line_error", "line error over time", plot_line_error),
    ("timeline", "which step ran when", plot_timeline),
)
"""(file stem, title, function(data, png path) -> reason skipped or None)."""


# -- the report -------------------------------------------------------------------------------------


__all__ = ["DPI", "FIG_SIZE_IN", "MAP_SIZE_IN", "PLOTS", "StepRun", "truth_at", "draw_path", "map_extent", "plot_clearance",
           "plot_path", "plot_line_error", "plot_position_error", "plot_saved_map", "plot_speeds", "plot_timeline", "position_errors", "step_intervals", "timeline_rows"]
