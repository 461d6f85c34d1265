"""``beastbt report`` and ``beastbt runs``: a run at a glance.

The plots must be real images: PNGs of the expected pixel size with content
(not blank, not one colour, with coloured data on them).
"""

from __future__ import annotations

import json

import pytest

from beastbt.cli import main
from beastbt.recording.report import (DPI, FIG_SIZE_IN, MAP_SIZE_IN, WAYPOINT_COLUMNS, RunData, draw_path,
                                      make_report, map_extent, position_errors, step_intervals, timeline_rows,
                                      waypoint_table)
from beastbt.recording.runs_list import list_runs
from recording_support import GPS_ROUTE, PATROL, assert_real_plot, record_run, shared_run

SIZES = {"path": MAP_SIZE_IN, "clearance": FIG_SIZE_IN, "position_error": FIG_SIZE_IN, "speeds": FIG_SIZE_IN, "line_error": FIG_SIZE_IN,
         "timeline": FIG_SIZE_IN}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A patrol and, when the example exists, a GPS route, both recorded (shortened), in one runs folder."""
    runs_dir = tmp_path_factory.mktemp("runs")
    out = {"dir": runs_dir, "patrol": record_run(PATROL, runs_dir, seed=1, max_time_s=35.0)}
    if GPS_ROUTE.exists():
        out["gps"] = shared_run("gps")
    return out


def test_report_on_a_patrol_makes_real_plots_and_a_page(runs, capsys):
    folder, summary = runs["patrol"]
    assert main(["report", str(folder)]) == 0
    text = capsys.readouterr().out
    assert "mission corridor_patrol: STOPPED" in text and "35.0 s" in text
    assert "failsafes: none" in text and "0 dropped" in text
    report_dir = folder / "report"
    made = {p.stem for p in report_dir.glob("*.png")}
    assert made == {"path", "clearance", "position_error", "speeds", "timeline"}  # no line was followed
    for stem in made:
        assert_real_plot(report_dir / f"{stem}.png", SIZES[stem], DPI)
    page = (report_dir / "report.html").read_text(encoding="utf-8")
    for stem in made:
        assert f"src='{stem}.png'" in page
    assert "line error over time: no line observations" in page


def test_the_timeline_follows_the_steps(runs):
    folder, _ = runs["patrol"]
    intervals = step_intervals(RunData.load(str(folder)))
    drives = [iv for iv in intervals if iv[0] == "drive 3 m at 0.15 m/s"]
    # The first drive: 3 m at 0.15 m/s takes about 20 s, from the first tick; it succeeded.
    assert drives[0][1] == 0.0 and 19.0 < drives[0][2] < 22.0 and drives[0][3] == "SUCCESS"
    turns = [iv for iv in intervals if iv[0] == "turn 180 deg"]
    assert turns and turns[0][1] > drives[0][2]
    # Nothing starts before it ends, and nothing is a reset of a step that was not running.
    assert all(iv.start_s < iv.end_s for iv in intervals)


def test_steps_that_share_a_name_get_a_row_each(runs):
    folder, _ = runs["patrol"]
    data = RunData.load(str(folder))
    intervals = step_intervals(data)
    # The patrol drives 3 m twice in each round: two steps of one name, told apart by their node ids.
    drives = [iv for iv in intervals if iv.name == "drive 3 m at 0.15 m/s"]
    nodes = {n["id"]: n for n in json.loads(data.rec.info["tree"])}
    assert len({iv.node_id for iv in drives}) == 2
    assert all(nodes[iv.node_id]["name"] == iv.name for iv in drives)
    first, second = sorted({iv.node_id for iv in drives}, key=lambda i: min(iv.start_s for iv in drives
                                                                           if iv.node_id == i))
    # The first one ran once (0-20 s, then the look around and the turn); the second one started after it.
    assert [iv.how for iv in drives if iv.node_id == first] == ["SUCCESS"]
    assert min(iv.start_s for iv in drives if iv.node_id == second) > max(iv.end_s for iv in drives
                                                                        if iv.node_id == first)
    rows = dict(timeline_rows(intervals))
    # Told apart in words, by the order they first ran: no node ids such as [0.0.0.1.0] on a person's plot.
    assert rows[first] == "drive 3 m at 0.15 m/s (1st)" and rows[second] == "drive 3 m at 0.15 m/s (2nd)"
    assert not any("[" in label for label in rows.values())


def _old_recording(path, changes_by_tick, tree):
    """An .mcap as recorded before the node ids: /tree changes and the tree's nodes by name only."""
    from mcap.writer import Writer
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="beastbt", library="test")
        w.add_metadata("beastbt.run", {"mission": "old_one", "rate_hz": "20.0", "tree": json.dumps(tree)})
        sid = w.register_schema(name="beastbt.Any", encoding="jsonschema", data=b"{}")
        tree_ch = w.register_channel(topic="/tree", message_encoding="json", schema_id=sid)
        gate_ch = w.register_channel(topic="/cmd/gate", message_encoding="json", schema_id=sid)
        for k in range(60):
            t = k * 0.05
            ns = round(t * 1e9)
            w.add_message(gate_ch, log_time=ns, publish_time=ns, data=json.dumps(
                {"tick": k, "now_s": t, "linear_mps": 0.1, "angular_rps": 0.0, "stamp_s": t, "source": "mission",
                 "mux_source": "mission"}).encode())
            if k in changes_by_tick:
                w.add_message(tree_ch, log_time=ns, publish_time=ns, data=json.dumps(
                    {"tick": k, "now_s": t, "changes": [{"name": n, "status": st, "feedback": ""}
                                                        for n, st in changes_by_tick[k]]}).encode())
        w.finish()


def test_a_recording_from_before_the_node_ids_still_makes_its_timeline(tmp_path):
    tree = [{"name": "steps", "kind": "Sequence", "depth": 0, "leaf": False},
            {"name": "wait 1 s", "kind": "Wait", "depth": 1, "leaf": True},
            {"name": "say hi", "kind": "Say", "depth": 1, "leaf": True}]
    _old_recording(tmp_path / "old.mcap", {0: [("steps", "RUNNING"), ("wait 1 s", "RUNNING")],
                                          20: [("wait 1 s", "SUCCESS"), ("say hi", "SUCCESS")],
                                          21: [("steps", "SUCCESS")]}, tree)
    data = RunData.load(str(tmp_path / "old.mcap"))
    intervals = step_intervals(data)
    assert [(iv.name, iv.start_s, iv.end_s, iv.how, iv.node_id) for iv in intervals] == [
        ("wait 1 s", 0.0, 1.0, "SUCCESS", None), ("say hi", 1.0, 1.05, "SUCCESS", None)]
    assert timeline_rows(intervals) == [("wait 1 s", "wait 1 s"), ("say hi", "say hi")]
    report = make_report(str(tmp_path / "old.mcap"))
    assert "timeline" in report.plots


@pytest.mark.skipif(not GPS_ROUTE.exists(), reason="no GPS route example yet")
def test_report_on_a_gps_route_shows_waypoints_and_gps(runs, tmp_path):
    folder, summary = runs["gps"]
    report = make_report(str(folder), str(tmp_path / "out"))
    assert report.folder == tmp_path / "out"
    assert {"path", "position_error", "speeds", "timeline"} <= set(report.plots)
    for stem, path in report.plots.items():
        assert_real_plot(path, SIZES[stem], DPI)
    assert summary["waypoints"], "the first place is reached within 55 s"
    for wp in summary["waypoints"]:
        line = next(x for x in report.text.splitlines() if x.strip().startswith(f"{wp['name']}:"))
        assert ("NOT reached" in line) != bool(wp["reached"])
        if wp["arrival_error_m"] is not None:
            assert f"{wp['arrival_error_m']:.2f} m off" in line
    data = RunData.load(str(folder))
    if data.rec.topic("/sensors/gps"):
        # GPS fixes land in local metres around the route, not at 0 deg N 0 deg E.
        frame = data.local_frame()
        e, n, _ = frame.to_enu(data.rec.topic("/sensors/gps")[-1]["lat"], data.rec.topic("/sensors/gps")[-1]["lon"])
        assert abs(e) < 200 and abs(n) < 200


def test_report_on_a_bare_mcap_and_on_a_run_cut_short(runs, tmp_path, capsys):
    folder, _ = runs["patrol"]
    data = (folder / "run.mcap").read_bytes()
    cut = tmp_path / "field.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    assert main(["report", str(cut)]) == 0
    out = capsys.readouterr().out
    assert "cut short" in out
    report_dir = tmp_path / "field_report"
    assert (report_dir / "report.html").exists() and (report_dir / "speeds.png").exists()
    assert_real_plot(report_dir / "speeds.png", FIG_SIZE_IN, DPI)


def test_report_without_truth_or_positions_leaves_those_plots_out(tmp_path):
    # A recording with only commands and the tree (as from a robot with no sensors recorded).
    from beastbt.recording.recorder import McapRecorder
    from beastbt.blackboard.types import VelocityCommand
    from beastbt.run.runner import TickRecord
    rec = McapRecorder([tmp_path / "bare.mcap"], info={"mission": "bare", "rate_hz": "20.0"})
    for k in range(40):
        cmd = VelocityCommand(0.1, 0.0, k * 0.05)
        rec.on_tick(TickRecord(k, k * 0.05, [], None, None, cmd, cmd, cmd, "mission",
                               [("wait 2 s", "RUNNING", "", "0")] if k == 0 else [], None))
    rec.finish(None)
    report = make_report(str(tmp_path / "bare.mcap"))
    assert set(report.plots) == {"speeds", "timeline"}
    assert set(report.skipped) == {"path", "saved_map", "clearance", "position_error", "line_error"}
    assert not (report.folder / "path.png").exists()


def test_runs_lists_each_run_with_its_outcome(runs, tmp_path, capsys):
    # An unfinished run: a folder with a recording and no summary (killed).
    unfinished = runs["dir"] / "20990101T000000Z_killed_run"
    unfinished.mkdir()
    (unfinished / "run.mcap").write_bytes((runs["patrol"][0] / "run.mcap").read_bytes()[:5000])
    entries = {e.folder.name: e for e in list_runs(str(runs["dir"]))}
    assert entries[runs["patrol"][0].name].status == "stopped"
    assert entries[unfinished.name].status == "unfinished" and entries[unfinished.name].mission == "killed_run"
    assert main(["runs", "--runs-dir", str(runs["dir"])]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("RUN") and len(lines) == len(entries) + 1
    line = next(x for x in lines if x.startswith(runs["patrol"][0].name))
    assert "corridor_patrol" in line and "stopped" in line and "35.0 s" in line and "MB" in line
    assert main(["runs", "--runs-dir", str(tmp_path / "none")]) == 0
    assert "no runs" in capsys.readouterr().out
    json.dumps([e.line() for e in entries.values()])


def test_line_error_is_plotted_when_a_line_was_followed(tmp_path):
    import math

    from beastbt.blackboard.types import LineObservation, VelocityCommand
    from beastbt.recording.recorder import McapRecorder
    from beastbt.run.runner import TickRecord
    rec = McapRecorder([tmp_path / "line.mcap"], info={"mission": "line", "rate_hz": "20.0"})
    for k in range(200):
        t = k * 0.05
        seen = k % 50 != 7  # lost for a tick now and then
        obs = LineObservation(t, seen, 0.03 * math.sin(t), 0.1 * math.cos(t), 0.02, 0.9 if seen else 0.0)
        cmd = VelocityCommand(0.2, -0.5 * obs.offset_m, t)
        rec.on_tick(TickRecord(k, t, [obs], None, None, cmd, cmd, cmd, "mission",
                               [("follow_line", "RUNNING", "", "0")] if k == 0 else [], None))
    rec.finish(None)
    report = make_report(str(tmp_path / "line.mcap"))
    assert "line_error" in report.plots
    assert_real_plot(report.plots["line_error"], FIG_SIZE_IN, DPI)


def test_report_on_a_camera_run_shows_the_line_and_the_snapshot(tmp_path):
    folder, _ = shared_run("camera")
    report = make_report(str(folder), str(tmp_path / "cam"))
    assert "line_error" in report.plots
    assert_real_plot(report.plots["line_error"], FIG_SIZE_IN, DPI)
    snap = tmp_path / "cam" / "snapshot_tape.jpg"
    assert snap.read_bytes() == (folder / "tape.jpg").read_bytes()
    assert "src='snapshot_tape.jpg'" in (tmp_path / "cam" / "report.html").read_text(encoding="utf-8")


# -- the report's views: map, GPS, waypoints, title ---------------------------------------------------


@pytest.fixture(scope="module")
def indoor(tmp_path_factory):
    """The patrol in the corridor on a simulated robot without a GPS (an indoor robot), 30 s."""
    import re

    from recording_support import REPO
    folder = tmp_path_factory.mktemp("indoor")
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    profile = folder / "sim_no_gps.yaml"
    profile.write_text(re.sub(r"\ngps:.*?\n(?=imu:)", "\n", text, flags=re.S), encoding="utf-8")
    run_folder, summary = record_run(PATROL, folder / "runs", seed=2, max_time_s=30.0, robot=str(profile),
                                     simulate=True)
    return run_folder, summary


def _drawn(data):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    labels = draw_path(data, ax)
    out = (labels, ax.get_xlim(), ax.get_ylim(), len(ax.collections))
    plt.close(fig)
    return out


def test_an_indoor_map_has_no_gps_and_is_scaled_to_the_truth(indoor):
    folder, _ = indoor
    data = RunData.load(str(folder))
    assert not data.rec.topic("/sensors/gps") and data.gps_fixes() == []
    labels, (x0, x1), (y0, y1), scatters = _drawn(data)
    assert not any(label.startswith("GPS") for label in labels) and scatters == 0
    assert {"truth", "walls", "start", "end"} <= set(labels)
    truth = data.rec.topic("/truth")
    tx = [m["x"] for m in truth]
    ty = [m["y"] for m in truth]
    # The whole true path is on the map, with a little room around it, and not much more: the corridor's
    # far end (x = 10 m) is left out, the walls do not set the scale.
    assert x0 < min(tx) and x1 > max(tx) and y0 < min(ty) and y1 > max(ty)
    assert x1 - x0 < max(tx) - min(tx) + 3.0 and x1 < 10.0
    assert x1 - x0 == pytest.approx(y1 - y0)  # square: a metre is a metre both ways


def test_gps_fixes_are_drawn_but_do_not_set_the_scale(runs):
    folder, _ = runs["gps"]
    data = RunData.load(str(folder))
    fixes = data.gps_fixes()
    assert fixes and len({m["time_utc"] for _, m in fixes}) == len(fixes)  # one per epoch
    labels, xlim, ylim, scatters = _drawn(data)
    assert f"GPS fixes ({len(fixes)})" in labels and scatters == 1
    with_gps = map_extent(data)
    assert (*xlim, *ylim) == pytest.approx(with_gps)
    # A wild fix far away changes nothing.
    t, far = fixes[-1]
    frame = data.local_frame()
    lat, lon, _ = frame.to_geodetic(500.0, 500.0, 0.0)
    data.rec.messages["/sensors/gps"].append((data.t0_ns + 10**9, {**far, "lat": lat, "lon": lon,
                                                                   "time_utc": "far"}))
    assert map_extent(data) == pytest.approx(with_gps)
    # The places the route goes to are on the map, with their tolerance circles.
    for name, e, n, tol, _ in data.targets():
        assert with_gps[0] <= e - tol and e + tol <= with_gps[1] and with_gps[2] <= n - tol and n + tol <= with_gps[3]


def test_the_position_error_has_the_raw_gps_beside_the_fused_estimate(runs, indoor):
    folder, summary = runs["gps"]
    errors = position_errors(RunData.load(str(folder)))
    assert {"fused estimate", "odometry", "raw GPS fix"} <= set(errors)
    times, errs = errors["raw GPS fix"]
    # The same fixes, the same truth as the run's own bookkeeping (parts/nav_summary.py), computed apart.
    assert len(errs) == summary["truth"]["gps_fixes"]
    rms = (sum(e * e for e in errs) / len(errs)) ** 0.5
    assert rms == pytest.approx(summary["truth"]["gps_error_rms_m"], rel=0.03)
    _, fused = errors["fused estimate"]
    assert (sum(e * e for e in fused) / len(fused)) ** 0.5 == pytest.approx(
        summary["truth"]["position_error_rms_m"], rel=0.03)
    assert times == sorted(times) and 0.0 <= times[0] < 5.0
    indoor_errors = position_errors(RunData.load(str(indoor[0])))
    assert "raw GPS fix" not in indoor_errors and "fused estimate" in indoor_errors


def test_the_waypoint_table_shows_tolerance_and_error(runs, tmp_path):
    folder, summary = runs["gps"]
    data = RunData.load(str(folder))
    rows = {row[0]: row for row in waypoint_table(data)}
    assert summary["waypoints"] and set(rows) == {wp["name"] for wp in summary["waypoints"]}
    for wp in summary["waypoints"]:
        row = dict(zip(WAYPOINT_COLUMNS, rows[wp["name"]]))
        assert row["tolerance (m)"] == f"{wp['tolerance_m']:.2f}"
        if wp["arrival_error_m"] is not None:
            # Both distances: the estimate's (judged against the tolerance, so within it for a reached place)
            # and the truth's (which adds the estimate's own error and may exceed it).
            assert row["true distance (m)"] == f"{wp['arrival_error_m']:.2f}"
            assert row["estimated distance (m)"] == f"{wp['estimated_error_m']:.2f}"
            assert wp["estimated_error_m"] <= wp["tolerance_m"]
    assert rows["a"][2] == "2.00"  # the mission gives a no tolerance: the profile's default
    page = make_report(str(folder), str(tmp_path / "out")).html.read_text(encoding="utf-8")
    assert "<th>tolerance (m)</th><th>estimated distance (m)</th><th>true distance (m)</th>" in page
    assert "counts as reached when the robot" in page and "fused estimate comes within the tolerance" in page
    assert "within tolerance" not in page  # the old column that said NO for a place the run rightly reached
    first = summary["waypoints"][0]
    assert f"<td>{first['name']}</td>" in page and f"<td class='num'>{first['tolerance_m']:.2f}</td>" in page
    # A summary from before tolerance_m: the mission's place tolerance (b: 3 m), else the default.
    data.summary = {**summary, "waypoints": [{k: v for k, v in wp.items() if k != "tolerance_m"}
                                             for wp in summary["waypoints"]] + [
        {"name": "b", "lat": 40.417, "lon": -3.7035, "reached": False, "arrival_error_m": None, "time_s": None}]}
    tolerances = {wp.name: wp.tolerance_m for wp in data.waypoints()}
    assert tolerances["b"] == 3.0 and tolerances["a"] == 2.0


def test_the_title_is_the_mission_and_the_date(runs, tmp_path):
    import datetime
    folder, _ = runs["patrol"]
    data = RunData.load(str(folder))
    mission, when = data.title().split(", ")
    assert mission == "corridor_patrol" and when.endswith(" UTC")
    # The run folder is named after the start time (UTC): the title's date and time agree with it.
    named = datetime.datetime.strptime(folder.name.split("_", 1)[0], "%Y%m%dT%H%M%SZ")
    titled = datetime.datetime.strptime(when, "%Y-%m-%d %H:%M UTC")
    assert abs((titled - named).total_seconds()) < 120
    page = make_report(str(folder), str(tmp_path / "out")).html.read_text(encoding="utf-8")
    assert f"<title>{data.title()}</title>" in page and f"<h1>{data.title()}</h1>" in page


def test_times_count_from_the_first_tick_whatever_the_time_base(tmp_path):
    # A recording whose clock is Unix time (as on a robot, or with an epoch time base), no start_utc.
    import datetime

    from beastbt.blackboard.types import VelocityCommand
    from beastbt.recording.recorder import McapRecorder
    from beastbt.run.runner import TickRecord
    start = 1_764_000_000.0  # 2025-11-24 16:00:00 UTC
    rec = McapRecorder([tmp_path / "epoch.mcap"], info={"mission": "epoch", "rate_hz": "20.0"})
    for k in range(40):
        t = start + k * 0.05
        cmd = VelocityCommand(0.1, 0.0, t)
        changes = {0: [("wait 1 s", "RUNNING", "", "0.0")], 20: [("wait 1 s", "SUCCESS", "", "0.0")]}
        rec.on_tick(TickRecord(k, t, [], None, None, cmd, cmd, cmd, "mission", changes.get(k, []), None))
    rec.finish(None)
    data = RunData.load(str(tmp_path / "epoch.mcap"))
    assert data.times("/cmd/gate")[0] == 0.0 and data.times("/cmd/gate")[-1] == pytest.approx(1.95)
    assert [(iv.start_s, iv.end_s) for iv in step_intervals(data)] == [(0.0, pytest.approx(1.0))]
    when = datetime.datetime.fromtimestamp(start, datetime.timezone.utc)
    assert data.title() == f"epoch, {when:%Y-%m-%d %H:%M} UTC"


def test_a_tree_put_in_during_the_run_shows_its_leaf_only(tmp_path):
    # A return_home replaces the mission's tree: its nodes ("1", "1.0") are not in the metadata's list.
    from beastbt.blackboard.types import VelocityCommand
    from beastbt.recording.recorder import McapRecorder
    from beastbt.run.runner import TickRecord
    tree = [{"id": "0", "name": "steps", "kind": "sequence", "parent": None},
            {"id": "0.0", "name": "go_to a", "kind": "action", "parent": "0"}]
    rec = McapRecorder([tmp_path / "home.mcap"], info={"mission": "home", "rate_hz": "20.0", "tree": json.dumps(tree)})
    changes = {0: [("steps", "RUNNING", "", "0"), ("go_to a", "RUNNING", "", "0.0")],
               10: [("steps", "INVALID", "", "0"), ("go_to a", "INVALID", "", "0.0"),
                    ("return home (failsafe)", "RUNNING", "", "1"), ("return_home", "RUNNING", "", "1.0")],
               30: [("return_home", "SUCCESS", "", "1.0")]}
    for k in range(40):
        cmd = VelocityCommand(0.1, 0.0, k * 0.05)
        rec.on_tick(TickRecord(k, k * 0.05, [], None, None, cmd, cmd, cmd, "mission", changes.get(k, []), None))
    rec.finish(None)
    intervals = step_intervals(RunData.load(str(tmp_path / "home.mcap")))
    assert [(iv.node_id, iv.name, iv.how) for iv in intervals] == [
        ("0.0", "go_to a", "INVALID"), ("1.0", "return_home", "SUCCESS")]
    assert intervals[1].start_s == pytest.approx(0.5) and intervals[1].end_s == pytest.approx(1.5)


def test_the_map_draws_the_fences_and_the_speeds_plot_turns_in_deg_per_s(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mission = GPS_ROUTE.read_text(encoding="utf-8")
    fenced = mission.replace("steps:", "fences:\n  yard: {keep: in, polygon: [{lat: 40.4166, lon: -3.7042}, "
                             "{lat: 40.4166, lon: -3.7030}, {lat: 40.4175, lon: -3.7030}, {lat: 40.4175, "
                             "lon: -3.7042}]}\nsteps:", 1)
    folder, _ = record_run(GPS_ROUTE, tmp_path / "runs", seed=3, max_time_s=20.0, mission_text=fenced)
    data = RunData.load(str(folder))
    (yard,) = data.fences()
    assert yard[0] == "yard" and yard[1] == "in" and len(yard[2]) == 4
    labels, (x0, x1), (y0, y1), _ = _drawn(data)
    assert "fence yard (keep in)" in labels
    assert all(x0 <= x <= x1 and y0 <= y <= y1 for x, y in yard[2])  # the map is wide enough to show it
    report = make_report(str(folder), str(tmp_path / "out"))
    assert "speeds" in report.plots
    from beastbt.recording import report as report_module
    drawn: list = []
    real_subplots = plt.subplots

    def spy(*args, **kwargs):
        fig, axes = real_subplots(*args, **kwargs)
        drawn.append(axes)
        return fig, axes

    plt.subplots = spy
    try:
        report_module.plot_speeds(data, tmp_path / "speeds.png")
    finally:
        plt.subplots = real_subplots
    (speed_ax, turn_ax), = drawn
    assert turn_ax.get_ylabel() == "turn rate (deg/s)"
    lines = {line.get_label(): line for line in turn_ax.get_lines()}
    mission_line, sent = lines["mission command"], lines["sent (after gate)"]
    assert mission_line.get_zorder() > sent.get_zorder() > lines["true turn rate"].get_zorder()  # asked, on top
    rates = [abs(v) for v in mission_line.get_ydata()]
    assert max(rates) > 5.0  # deg/s: a route's turns, not the 0.1-1 of rad/s

