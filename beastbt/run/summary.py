"""The run summary: the JSON that scripts read after a run (``schemas/summary.schema.json``)."""

from __future__ import annotations

import math
from typing import Any, Optional



def build_summary(run: Any, seed: int, wall_time_s: float, world_name: Optional[str], robot_name: str) -> dict:
    """The summary of a finished :class:`~beastbt.run.runner.MissionRun`."""
    sim = run.io.sim
    pose = run.bb.pose_odom
    if sim is not None:
        distance = sim.drive.path_length_m
        max_speed = sim.drive.max_speed_mps
    else:
        distance = pose.distance_m if pose is not None else 0.0
        max_speed = getattr(run, "max_speed_seen_mps", 0.0)
    summary: dict = {
        "mission": run.mission.name,
        "status": run.status or "stopped",
        "seed": seed,
        "robot": robot_name,
        "world": world_name,
        "sim_time_s": round(run.elapsed_s, 3),
        "wall_time_s": round(wall_time_s, 3),
        "ticks": run.ticks,
        "distance_m": round(distance, 4),
        "max_speed_mps": round(max_speed, 4),
        "waypoints": [],
        "events": [e.as_dict() for e in run.events.events],
        "servos": {},
    }
    if run.events.dropped:
        summary["events_dropped"] = run.events.dropped
    esp32 = run.io.esp32
    if esp32 is not None:
        summary["servos"] = {name: list(v) for name, v in esp32.gimbal.visits.items()}
        dropped = {name: v.dropped for name, v in esp32.gimbal.visits.items() if getattr(v, "dropped", 0)}
        if dropped:  # a long run keeps the first and the last settled angles of each servo
            summary["servos_dropped"] = dropped
    if sim is not None:
        t = sim.truth
        summary["truth"] = {
            "final_pose": {"x": round(t.x, 4), "y": round(t.y, 4), "yaw_deg": round(math.degrees(t.yaw), 3)},
            "distance_m": round(distance, 4),
            "blocked": bool(sim.drive.blocked),
        }
        contact = sim.drive.contact  # None in a world with nothing to touch: no contact, no clearance
        least = contact.min_clearance_m if contact is not None else None
        summary["truth"]["collisions"] = contact.collisions if contact is not None else 0
        summary["truth"]["min_clearance_m"] = None if least is None else round(least, 4) + 0.0  # + 0.0: no -0.0
    home = getattr(run, "home_set", None)
    if home is not None:  # how home was set: the fused start once settled (beastbt/run/home.py)
        summary["home"] = home.as_dict()
    for contribute in run.summary_contributors:  # the parts' fields (waypoints, truth metrics, recording...)
        contribute(run, summary)
    return summary


def waypoint_text(name: str, reached: bool, tolerance_m: Optional[float], estimated_error_m: Optional[float],
                  true_error_m: Optional[float], time_s: Optional[float]) -> str:
    """One place visited, in words: reached or not, when (mission s), and how far off (m), saying that arrival is
    judged on the estimate (within the tolerance) and, in the simulator, how far the robot truly was."""
    if not reached:
        return f"{name}: NOT reached"
    text = f"{name}: reached" + (f" at {time_s:.1f} s" if time_s is not None else "")
    judged = []
    if estimated_error_m is not None:
        judged.append(f"{estimated_error_m:.2f} m off by the estimate")
    if tolerance_m is not None:
        judged.append(f"tolerance {tolerance_m:.2f} m")
    if judged:
        text += " (arrival is judged on the estimate: " + ", ".join(judged) + ")"
    if true_error_m is not None:
        text += f"; truly {true_error_m:.2f} m off"
        if tolerance_m is not None and true_error_m > tolerance_m:
            text += " (beyond the tolerance by the estimate's own error)"
    return text


def summary_waypoint_text(wp: dict, simulated: bool) -> str:
    """:func:`waypoint_text` of one of the summary's ``waypoints`` (``simulated``: the summary has ``truth``, so
    ``arrival_error_m`` is the true distance; summaries from before ``estimated_error_m`` lack the estimate's)."""
    err = wp.get("arrival_error_m")
    estimated = wp.get("estimated_error_m", None if simulated else err)
    return waypoint_text(str(wp.get("name", "?")), bool(wp.get("reached")), wp.get("tolerance_m"), estimated,
                         err if simulated else None, wp.get("time_s"))


def obstacles_line(s: dict) -> Optional[str]:
    """The summary's obstacle figures in one line: the simulator's collisions and least clearance, and what the
    collision monitor did (episodes per action); None when the run has neither."""
    parts = []
    truth = s.get("truth") or {}
    if "collisions" in truth:
        n = truth["collisions"]
        least = truth.get("min_clearance_m")
        parts.append(f"{n} collision{'s' if n != 1 else ''}"
                     + (f", least clearance {least:.2f} m" if least is not None else "") + " (truth)")
    episodes = (s.get("collision_monitor") or {}).get("episodes") or {}
    if s.get("collision_monitor") is not None:
        said = ", ".join(f"{action} {count}" for action, count in sorted(episodes.items()))
        parts.append("collision monitor: " + (said if said else "never acted"))
    return "  obstacles: " + "; ".join(parts) if parts else None


def has_obstacles(s: dict) -> bool:
    """Whether the terminal summary speaks of obstacles: the robot has a LiDAR (the collision monitor's fields),
    or the world has walls or obstacles (a least clearance), or something was hit."""
    truth = s.get("truth") or {}
    return (s.get("collision_monitor") is not None or truth.get("min_clearance_m") is not None
            or bool(truth.get("collisions")))


def dock_text(d: dict) -> str:
    """One of the summary's ``vision.docks`` in words: how it ended, and how far from the goal by the estimate and
    (in the simulator) truly."""
    text = f"dock at tag {d.get('tag')}: {d.get('status', '?')} at {float(d.get('time_s', 0.0)):.1f} s"
    if d.get("error_m") is not None:
        text += (f", {float(d['error_m']) * 100:.1f} cm and {float(d.get('error_deg', 0.0)):.1f} deg off the goal by the "
                 "estimate")
    truth = d.get("truth") or {}
    if truth.get("error_m") is not None:
        text += f"; truly {float(truth['error_m']) * 100:.1f} cm and {float(truth.get('error_deg', 0.0)):.1f} deg"
    if d.get("retries"):
        text += f" (after {d['retries']} {'retry' if d['retries'] == 1 else 'retries'})"
    return text


def vision_lines(summary: dict) -> list[str]:
    """The camera's words in the summary, a line each: every dock, the photos taken, the alerts (the last one's
    text)."""
    vision = summary.get("vision") or {}
    lines = ["  " + dock_text(d) for d in vision.get("docks") or []]
    photos = vision.get("photos") or []
    if photos:
        names = [str(p.get("name")) for p in photos]
        lines.append(f"  photos: {len(photos)} ({', '.join(names[:6])}{', ...' if len(names) > 6 else ''})")
    alerts = summary.get("alerts") or []
    if alerts:
        last = alerts[-1]
        lines.append(f"  alerts: {len(alerts)}, the last at {float(last.get('time_s', 0.0)):.1f} s: {last.get('text')}")
    return lines


def human_summary(summary: dict) -> str:
    """A few lines for a person at the end of a run.

    The end itself is said once, in the first line (the mission_end event was
    printed as it happened); its time is that event's, so the two agree. Then
    how home was set, the places visited (arrival judged on the estimate; the
    true distance in the simulator), collisions and clearance when the robot
    has a LiDAR or the world has obstacles, the docks, photos and alerts. The failures before the end (last
    five) are repeated for whoever scrolled past them.
    """
    from beastbt.run.home import home_line
    events = summary["events"]
    end = next((e for e in reversed(events) if e["kind"] == "mission_end"), None)
    why = end["text"].split(": ", 1)[1] if end is not None and ": " in end["text"] else None
    time_s = end["time_s"] if end is not None else summary["sim_time_s"]
    lines = [
        f"mission {summary['mission']}: {summary['status'].upper()}" + (f" ({why})" if why else ""),
        f"  time {time_s:.1f} s (wall {summary['wall_time_s']:.2f} s, {summary['ticks']} ticks)",
        f"  distance {summary['distance_m']:.2f} m, top speed {summary['max_speed_mps']:.2f} m/s",
    ]
    loc = summary.get("localisation")
    if loc is not None:
        rms = (summary.get("truth") or {}).get("position_error_rms_m")
        lines.append(f"  localisation: {'localised' if loc['localized'] else 'NOT localised'} at the end, match "
                     f"{loc['match_quality']:.0%}, {loc['updates']} updates"
                     + (f"; true error RMS {rms:.3f} m" if rms is not None else ""))
    if summary.get("home") is not None:
        lines.append(home_line(summary["home"]))
    simulated = "truth" in summary
    for wp in summary.get("waypoints", []):
        lines.append("  waypoint " + summary_waypoint_text(wp, simulated))
    if has_obstacles(summary):
        lines.append(obstacles_line(summary) or "  obstacles: none seen")
    lines.extend(vision_lines(summary))
    ends = [e for e in events if e["kind"] in ("step_failed", "failsafe", "estop")]
    for e in ends[-5:]:
        lines.append(f"  [{e['time_s']:7.1f} s] {e['kind']}: {e['text']}")
    return "\n".join(lines)
