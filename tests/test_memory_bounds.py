"""A ``forever`` mission's memory stays bounded (issue 25, point 4).

A robot on ``repeat: forever`` runs for days. What a run keeps per tick, per
command or per step must not grow with its length: the emulated base's log of
commands and bytes, the gimbal's settled angles (the summary's ``servos``),
the events, the place visits (``waypoints``). Each keeps a bounded part (the
latest, or the first and the last) and counts the rest. The soak benchmark
(``benchmarks/soak_memory.py``) measures the process's RSS over 10 simulated
hours; here the same patrol runs for an hour in-process and the bounded
structures and the traced Python memory are checked.
"""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from beastbt.assembly import prepare
from beastbt.core.bounded import HeadTail, trim_front
from beastbt.core.clock import SimClock
from beastbt.core.events import EventLog
from beastbt.run.session import RunOptions
from beastbt.run.summary import build_summary
from beastbt.sim import waveshare_emulator
from beastbt.sim.serial_port import WRITTEN_KEPT_BYTES
from conftest import REPO

PATROL = f"""
mission: patrol_forever
world: {REPO / "worlds" / "campus.yaml"}
limits: {{speed: 0.3 m/s}}
steps:
  - repeat:
      times: forever
      steps:
        - drive: {{distance: 3 m, speed: 0.15 m/s}}
        - look: {{pan: -45 deg}}
        - look: {{pan: 45 deg}}
        - look: {{pan: 0 deg}}
        - turn: {{angle: 180 deg}}
"""
"""The shipped patrol's pattern looping forever, in the open campus world (the corridor's walls end it)."""


def _prepared(tmp_path: Path):
    return prepare(str(tmp_path / "mission.yaml"), RunOptions(record=False), mission_text=PATROL)


def _advance(p, seconds: float) -> None:
    run, clock = p.run, p.clock
    dt = 1.0 / p.mission.rate_hz
    end = run.elapsed_s + seconds
    while run.status is None and run.elapsed_s < end:
        run.tick()
        clock.advance(dt)
    assert run.status is None, "the forever patrol must still be running"


def _sizes(p) -> dict:
    esp32 = p.run.io.esp32
    return {"commands": len(esp32.commands), "written": len(esp32.port.written),
            "pan": len(esp32.gimbal.visits["pan"]), "events": len(p.run.events.events)}


def test_a_forever_patrol_keeps_bounded_logs_and_its_traced_memory_stays_flat(tmp_path):
    p = _prepared(tmp_path)
    esp32 = p.run.io.esp32
    _advance(p, 1800.0)
    half = _sizes(p)
    tracemalloc.start(1)  # it slows every allocation: trace a shorter window
    try:
        _advance(p, 120.0)
        before, _ = tracemalloc.get_traced_memory()
        _advance(p, 600.0)
        after, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    _advance(p, 1800.0 - 720.0)
    full = _sizes(p)
    # Ten minutes of patrol (about 14 loops, a command to the base at every tick) leave the traced heap
    # where it was (before the bounds: about 3.4 MB, every command and byte sent to the base).
    assert after - before < 1_000_000, f"traced Python memory grew {after - before} bytes in 10 simulated minutes"
    # The hour produced far more than is kept: the bounds bit...
    assert esp32.commands_total > 10 * waveshare_emulator.COMMANDS_KEPT
    assert esp32.port.written_total > 2 * WRITTEN_KEPT_BYTES
    # ...and what is kept did not grow with the run's length between its first and its second half hour.
    assert full["commands"] == half["commands"] == waveshare_emulator.COMMANDS_KEPT
    assert full["written"] <= 2 * WRITTEN_KEPT_BYTES
    assert full["pan"] <= 2 * waveshare_emulator.VISITS_KEPT
    assert full["events"] == half["events"]


def test_the_summary_keeps_the_first_and_last_servo_angles_and_says_how_many_it_left_out(tmp_path, monkeypatch):
    monkeypatch.setattr(waveshare_emulator, "VISITS_KEPT", 4)
    p = _prepared(tmp_path)
    _advance(p, 300.0)
    s = build_summary(p.run, 0, 0.0, "campus", p.profile.name)
    pan = s["servos"]["pan"]
    assert len(pan) == 8 and s["servos_dropped"]["pan"] > 0
    assert pan[:3] == [-45.0, 45.0, 0.0]  # the first of the patrol's looks, then the latest
    assert set(pan) == {-45.0, 45.0, 0.0}
    assert s["servos_dropped"]["pan"] + len(pan) == p.run.io.esp32.gimbal.visits["pan"].total
    schema = json.loads((REPO / "schemas" / "summary.schema.json").read_text(encoding="utf-8"))
    jsonschema.validate(s, schema)


def test_an_event_log_keeps_how_the_run_began_and_how_it_ended():
    clock = SimClock()
    log = EventLog(clock, max_events=6)
    seen = []
    log.listeners.append(seen.append)
    log.add("mission_start", "started")
    for i in range(100):
        clock.advance(1.0)
        log.add("say", f"loop {i}")
    log.add("mission_end", "stopped: max time")
    assert [e.text for e in log.events] == ["started", "loop 0", "loop 1", "loop 98", "loop 99", "stopped: max time"]
    assert log.dropped == 96 and log.events.total == 102
    assert log.last("mission_end").text == "stopped: max time" and log.last("say").text == "loop 99"
    assert len(seen) == 102  # the listeners (console, recording) see every event


def test_head_tail_keeps_both_ends_in_order():
    h: HeadTail[int] = HeadTail(2, 3)
    for i in range(10):
        h.append(i)
    assert list(h) == [0, 1, 7, 8, 9] and list(reversed(h)) == [9, 8, 7, 1, 0]
    assert (len(h), h.dropped, h.total) == (5, 5, 10)
    assert (h[0], h[1], h[2], h[-1]) == (0, 1, 7, 9)
    assert h[-2:] == [8, 9] and h[1:4] == [1, 7, 8]
    with pytest.raises(IndexError):
        h[5]
    only_head: HeadTail[int] = HeadTail(2, 0)
    for i in range(5):
        only_head.append(i)
    assert list(only_head) == [0, 1] and only_head.dropped == 3


def test_trim_front_keeps_the_latest_between_keep_and_twice_keep():
    log = list(range(21))
    trim_front(log, 10)
    assert log == list(range(11, 21))
    log = list(range(20))
    trim_front(log, 10)
    assert len(log) == 20  # not over twice keep yet: nothing let go


def test_line_metrics_stay_exact_until_their_bound_then_read_the_p95_off_a_histogram(monkeypatch):
    from beastbt.run import line_metrics
    monkeypatch.setattr(line_metrics, "EXACT_SAMPLES", 50)
    rng = np.random.default_rng(3)
    errors = np.abs(rng.normal(0.0, 0.03, 400))
    short = line_metrics.LineTruthMetrics(lambda: None, [])
    for e in errors[:50]:
        short.add(float(e))
    s = short.summary()
    assert s["line_error_p95_m"] == round(float(np.percentile(errors[:50], 95)), 4)  # exact, as before
    assert "line_error_p95_resolution_m" not in s
    long = line_metrics.LineTruthMetrics(lambda: None, [])
    for e in errors:
        long.add(float(e))
    s = long.summary()
    assert len(long.errors_m) == 50 and s["line_samples"] == 400
    assert abs(s["line_error_p95_m"] - np.percentile(errors, 95)) <= line_metrics.HISTOGRAM_BIN_M
    assert s["line_error_p95_resolution_m"] == line_metrics.HISTOGRAM_BIN_M
    assert s["line_within_5cm_frac"] == round(float((errors <= 0.05).mean()), 4)  # running totals stay exact
    assert s["line_error_max_m"] == round(float(errors.max()), 4)


def test_a_route_that_loops_forever_keeps_its_first_and_last_visits_in_the_summary(monkeypatch):
    from types import SimpleNamespace

    from beastbt.behaviours import navigation
    from beastbt.parts.nav_summary import contribute
    monkeypatch.setattr(navigation, "VISITS_KEPT", 4)
    log = navigation.VisitLog()
    for i in range(10):
        visit = log.start(f"p{i}", 40.4168, -3.7038, 2.0)
        visit.reached, visit.time_s, visit.estimated_error_m = True, float(i), 0.5
        log.end(visit)
    run = SimpleNamespace(ctx=SimpleNamespace(services=SimpleNamespace(nav_visits=log, nav_truth=None)))
    summary: dict = {}
    contribute(run, summary)
    assert [w["name"] for w in summary["waypoints"]] == ["p0", "p1", "p8", "p9"]
    assert summary["waypoints_dropped"] == 6
