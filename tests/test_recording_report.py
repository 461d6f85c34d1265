"""``beastbt report`` and ``beastbt runs``: a run at a glance.

The plots must be real images: PNGs of the expected pixel size with content
(not blank, not one colour, with coloured data on them).
"""

from __future__ import annotations

import json

import pytest

from beastbt.cli import main
from beastbt.recording.report import (DPI, FIG_SIZE_IN, MAP_SIZE_IN, RunData, make_report, step_intervals,
                                      timeline_rows)
from beastbt.recording.runs_list import list_runs
from recording_support import GPS_ROUTE, PATROL, assert_real_plot, record_run, shared_run

SIZES = {"path": MAP_SIZE_IN, "position_error": FIG_SIZE_IN, "speeds": FIG_SIZE_IN, "line_error": FIG_SIZE_IN,
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
    assert made == {"path", "position_error", "speeds", "timeline"}  # no line was followed
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
    assert rows[first] == f"drive 3 m at 0.15 m/s [{first}]" and rows[second] == f"drive 3 m at 0.15 m/s [{second}]"


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
    assert set(report.skipped) == {"path", "position_error", "line_error"}
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
    assert len(lines) == len(entries)
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
