"""route, return_home, the gps_lost hold, going home after a failure, and the A-B-C mission end to end."""

from __future__ import annotations

import json
import math

import pytest

from beastbt import cli
from beastbt.blackboard.types import GpsFix
from beastbt.estimation.geodesy import distance_m
from beastbt.estimation.gps_epochs import EpochFilter
from conftest import REPO
from nav_support import events_of, harness, place_yaml, true_distance_to_home_m

GPS_ROUTE = REPO / "missions" / "gps_route.yaml"


def test_route_visits_the_places_in_order_loops_times(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 12.0)}
  b: {place_yaml(6.0, 6.0, "1.5 m")}
steps:
  - route: {{places: [a, b], loops: 2}}
""")
    route = h.node("route a -> b (2 times)")
    assert [n.name for n in route.iterate()] == ["go_to a (within 2 m)", "go_to b (within 1.5 m)", "pass",
                                                 "route a -> b (2 times)"]
    assert h.run_to_end(timeout_s=600) == "success"
    wp = h.summary()["waypoints"]
    assert [(w["name"], w["reached"]) for w in wp] == [("a", True), ("b", True), ("a", True), ("b", True)]
    times = [w["time_s"] for w in wp]
    assert times == sorted(times) and len(set(times)) == 4
    assert all(w["arrival_error_m"] < (1.5 if w["name"] == "b" else 2.0) + 1.5 for w in wp)


def test_route_forever_keeps_going(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 12.0)}
  b: {place_yaml(0.0, 4.0)}
steps:
  - route: {{places: [a, b], loops: forever}}
""")
    assert h.node("route a -> b (forever)").status.name == "INVALID"
    visits = h.run.ctx.services.nav_visits.visits
    assert h.tick_until(lambda h: sum(v.reached for v in visits) >= 5, timeout_s=600)
    assert h.result is None and h.status_of("route a -> b (forever)") == "RUNNING"


def test_return_home_drives_back_to_the_first_fix(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(4.0, 14.0)}
steps:
  - go_to: a
  - return_home: {{tolerance: 1.5 m}}
""")
    assert h.run_to_end(timeout_s=400) == "success"
    home = h.run.home
    assert home is not None and events_of(h, "home")
    wp = h.summary()["waypoints"]
    assert [w["name"] for w in wp] == ["a", "home"] and all(w["reached"] for w in wp)
    assert (wp[1]["lat"], wp[1]["lon"]) == (round(home[0], 8), round(home[1], 8))
    # home is the first fix, reached within 1.5 m by the estimate
    assert true_distance_to_home_m(h) < 1.5 + 1.5
    assert h.status_of("return_home (within 1.5 m)") == "SUCCESS"


def test_gps_lost_hold_stops_and_resumes_the_same_go_to(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  far: {place_yaml(0.0, 22.0)}
steps:
  - go_to: far
failsafes:
  gps_lost: {{after: 3 s, then: hold}}
""", gps={"dropouts_s": [[60.0, 70.0]]})
    node = h.node("go_to far (within 2 m)")
    assert h.tick_until(lambda h: h.run.paused_by is not None, timeout_s=80)
    held_at = h.now_s
    assert 62.0 <= held_at <= 62.5                      # last fix at 59 s, gps_lost after 3 s
    pos = (h.truth.x, h.truth.y)
    h.tick(60)                                          # 3 s of hold
    assert h.run.paused_by == "hold (gps_lost)"
    assert all(c.is_zero() for c in h.sent[-20:])       # stopped
    assert math.hypot(h.truth.x - pos[0], h.truth.y - pos[1]) < 0.1
    assert node.status.name == "RUNNING"                # not stopped, just not ticked
    assert h.tick_until(lambda h: h.run.paused_by is None, timeout_s=15)
    assert 70.0 <= h.now_s <= 71.5
    assert h.run_to_end(timeout_s=200) == "success"
    texts = [e.text for e in events_of(h, "failsafe")]
    assert texts == ["gps_lost triggered: then hold", "gps_lost cleared", "resuming the mission"]
    assert [w["name"] for w in h.summary()["waypoints"]] == ["far"]    # one visit: it carried on
    assert not events_of(h, "step_failed")                             # the pause did not count as stuck


def test_on_failure_return_home_goes_home_and_the_run_still_fails(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 14.0)}
  b: {place_yaml(10.0, 14.0)}
steps:
  - go_to: a
  - go_to: {{place: b, gps_timeout: 3 s}}
on_failure: return_home
""", gps={"dropouts_s": [[75.0, 82.0]]})
    assert h.tick_until(lambda h: h.status_of("go_to a (within 2 m)") == "SUCCESS", timeout_s=75)
    assert h.run_to_end(timeout_s=600) == "failure"
    failed = events_of(h, "step_failed")
    assert len(failed) == 1 and "go_to b" in failed[0].text and "no GPS fix for 3 s" in failed[0].text
    assert events_of(h, "return_home")[0].text.startswith("going home: steps failed at go_to b")
    assert "returned home" in events_of(h, "mission_end")[0].text
    wp = h.summary()["waypoints"]
    assert [(w["name"], w["reached"]) for w in wp] == [("a", True), ("b", False), ("home", True)]
    assert true_distance_to_home_m(h) < 2.0 + 1.5


def test_a_failsafe_with_then_return_home_takes_the_robot_home(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  far: {place_yaml(0.0, 30.0)}
steps:
  - go_to: far
failsafes:
  geofence: {{center: home, radius: 12 m, then: return_home}}
""")
    assert h.run_to_end(timeout_s=600) == "failure"
    assert events_of(h, "failsafe")[0].text == "geofence triggered: then return_home"
    assert "failsafe geofence; returned home" in events_of(h, "mission_end")[0].text
    assert [w["name"] for w in h.summary()["waypoints"]] == ["far", "home"]
    assert true_distance_to_home_m(h) < 2.0 + 1.5


def test_epoch_filter_passes_one_fix_per_epoch():
    def fix(t, sentence, time_utc, track=None):
        return GpsFix(t, 1.0, 2.0, sentence=sentence, time_utc=time_utc, track_deg=track)
    f = EpochFilter()
    # the first epoch: GGA before any date (no time), then RMC with the date: one epoch, the RMC kept
    out = f([fix(1.0, "GGA", None), fix(1.0, "RMC", "T1", 90.0)])
    assert [x.sentence for x in out] == ["RMC"]
    # an epoch split across two polls: the second half is dropped
    assert [x.sentence for x in f([fix(2.0, "GGA", "T2")])] == ["GGA"]
    assert f([fix(2.05, "RMC", "T2", 91.0)]) == []
    # two epochs in one poll (10 Hz receiver, slow poll): both, each once
    out = f([fix(3.0, "GGA", "T3"), fix(3.0, "RMC", "T3"), fix(3.0, "GGA", "T4"), fix(3.0, "RMC", "T4")])
    assert [(x.sentence, x.time_utc) for x in out] == [("RMC", "T3"), ("RMC", "T4")]
    assert f.dropped == 4


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_abc_route_reaches_every_waypoint(tmp_path, seed):
    out = tmp_path / "s.json"
    code = cli.main(["run", str(GPS_ROUTE), "--seed", str(seed), "--summary", str(out), "--no-record"])
    s = json.loads(out.read_text())
    assert code == 0 and s["status"] == "success"
    names = [w["name"] for w in s["waypoints"]]
    assert names == ["a", "b", "c", "home"] and all(w["reached"] for w in s["waypoints"])
    tolerance = {"a": 2.0, "b": 3.0, "c": 2.0, "home": 2.0}
    for w in s["waypoints"]:
        assert 0.0 <= w["arrival_error_m"] < tolerance[w["name"]] + 1.5
        assert w["tolerance_m"] == tolerance[w["name"]]  # b's own 3 m, else the profile's default
    # the places are those of the mission; home is the first fix, near the world's datum
    assert (s["waypoints"][1]["lat"], s["waypoints"][1]["lon"]) == (40.417, -3.7035)
    assert distance_m(s["waypoints"][3]["lat"], s["waypoints"][3]["lon"], 40.4168, -3.7038) < 10.0
    truth = s["truth"]
    assert truth["position_error_rms_m"] < 0.5 * truth["gps_error_rms_m"]
    assert truth["gps_fixes"] > 400
