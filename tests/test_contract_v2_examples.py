"""Every example of the contract's "mission language, v2 additions" validates and runs on the simulator.

The fragments below are copied verbatim from ``MISSION_LANGUAGE.md`` (the
design's contract, section by section). Each is set in the least context it
needs to be a mission: places near the world's datum, the files it names,
and, for ``ask``, steps in place of the contract's ``[ ... ]`` placeholder.
Each is checked with ``beastbt validate`` (exit 0) and run with ``beastbt run``
on the simulator, as a user would; nobody answers the questions, so an
``ask`` resolves by its timeout and default.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import yaml

from beastbt.estimation.geodesy import LocalFrame
from conftest import REPO

GUARDS = """\
- until: {near: gate, within: 4 m}
  steps:
    - follow_line: {speed: 0.15 m/s, until: line_end}
- abort_if: {battery_below: 10.5 V}
  steps:
    - route: {places: [a, b, c], loops: forever}
"""

TASKS = """\
tasks:
  look_side:
    params: {angle: 45 deg, hold: 2 s}     # the defaults; every parameter needs one
    steps:
      - look: {pan: $angle}
      - wait: $hold
      - look: {pan: 0 deg}
steps:
  - do: look_side                          # the defaults
  - do: {task: look_side, angle: -30 deg}  # one parameter set
"""

ASK = """\
- ask:
    id: door                # optional; needed to answer it from a script
    question: Is the door open?
    timeout: 60 s           # optional; without it the mission waits
    default: no             # the answer when the timeout passes: yes | no
  then: [ ... ]             # on yes
  else: [ ... ]             # on no (optional)
"""

FENCES = """\
fences:
  yard: {polygon: [a, b, c, d]}                 # places, or {lat, lon} pairs
  pond: {file: pond.kml, keep: out}             # a keep-out zone from a file
  site: {file: site.geojson}                    # Polygon or the first polygon
failsafes:
  geofence: {fence: yard, margin: 1 m, then: stop}
  keepout: {fence: pond, then: hold}
"""

FILES = """\
places: {file: survey.gpx}                       # named places: GPX wpt, KML Placemark points, GeoJSON Point features with a name
steps:
  - route: {file: field_path.gpx, speed: 0.3 m/s}   # GPX rte or trk, KML LineString, GeoJSON LineString,
                                                    # QGroundControl .plan (NAV_WAYPOINT items), Mission Planner .waypoints (QGC WPL 110)
  - route: {places: [a, b], resume: nearest}      # after a hold or takeover: nearest (the closest remaining point) or current (default)
  - return_home: {along: path}                    # retrace the path driven (like ArduPilot's SmartRTL); default: straight
"""


def frame_of(world: str) -> LocalFrame:
    datum = (yaml.safe_load((REPO / "worlds" / world).read_text()) or {}).get("datum") or {"lat": 0.0, "lon": 0.0}
    return LocalFrame(float(datum["lat"]), float(datum["lon"]))


def place(frame: LocalFrame, east_m: float, north_m: float) -> dict:
    lat, lon, _ = frame.to_geodetic(east_m, north_m, 0.0)
    return {"lat": round(lat, 8), "lon": round(lon, 8)}


def check(tmp_path: Path, text: str, max_time: str, answers_expected: bool = True) -> dict:
    path = tmp_path / "example.yaml"
    path.write_text(text, encoding="utf-8")
    ok = subprocess.run([sys.executable, "-m", "beastbt", "validate", str(path)], capture_output=True, text=True,
                        timeout=120)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    summary = tmp_path / "summary.json"
    run = subprocess.run([sys.executable, "-m", "beastbt", "run", str(path), "--no-record", "--max-time", max_time,
                          "--summary", str(summary)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode in (0, 1), run.stdout + run.stderr
    assert "Traceback" not in run.stderr
    return json.loads(summary.read_text())


def test_guards_halt_the_running_step(tmp_path):
    frame = frame_of("line_track.yaml")
    places = {"gate": place(frame, 2.5, 2.5), "a": place(frame, 1.0, 0.0), "b": place(frame, 3.0, 0.0),
              "c": place(frame, 3.0, 2.0)}
    # ``near`` needs a position on Earth: the line track, laid out under the open sky.
    outdoors = tmp_path / "line_track_outdoors.yaml"
    outdoors.write_text("".join(line for line in (REPO / "worlds" / "line_track.yaml").read_text().splitlines(True)
                                if not line.startswith("gps:")), encoding="utf-8")
    text = (f"mission: guards\nworld: {outdoors}\nplaces: {json.dumps(places)}\n"
            "steps:\n" + textwrap.indent(GUARDS, "  "))
    summary = check(tmp_path, text, "90 s")
    guards = [e["text"] for e in summary["events"] if e["kind"] == "guard"]
    assert guards, summary["events"][-5:]  # a guard halted a running step (the line, or the endless route)


def test_tasks_with_parameters(tmp_path):
    summary = check(tmp_path, "mission: tasks_with_params\n" + TASKS, "60 s")
    assert summary["status"] == "success"
    assert summary["servos"]["pan"] == [45.0, 0.0, -30.0, 0.0]  # the default, then the parameter set
    assert summary["sim_time_s"] >= 4.0  # two holds of 2 s (the default)


def test_asking_the_operator_resolves_by_its_default_when_nobody_answers(tmp_path):
    fragment = ASK.replace("then: [ ... ]", "then: [{say: open}]").replace("else: [ ... ]", "else: [{say: closed}]")
    summary = check(tmp_path, "mission: ask_door\nsteps:\n" + textwrap.indent(fragment, "  "), "120 s")
    assert summary["status"] == "success"
    texts = [(e["kind"], e["text"]) for e in summary["events"]]
    assert ("answer", "door: no (by timeout)") in texts and ("say", "closed") in texts


def test_fences_from_places_and_files(tmp_path):
    frame = frame_of("campus.yaml")
    corners = {"a": place(frame, -10, -10), "b": place(frame, 40, -10), "c": place(frame, 40, 40),
               "d": place(frame, -10, 40), "goal": place(frame, 10, 10)}
    pond = [place(frame, x, y) for x, y in ((25, 25), (35, 25), (35, 35), (25, 35))]
    coords = " ".join(f"{p['lon']},{p['lat']},0" for p in pond + pond[:1])
    (tmp_path / "pond.kml").write_text(
        '<kml xmlns="http://www.opengis.net/kml/2.2"><Document><Placemark><name>pond</name><Polygon>'
        f'<outerBoundaryIs><LinearRing><coordinates>{coords}</coordinates></LinearRing></outerBoundaryIs>'
        '</Polygon></Placemark></Document></kml>', encoding="utf-8")
    site = [place(frame, x, y) for x, y in ((-20, -20), (50, -20), (50, 50), (-20, 50))]
    (tmp_path / "site.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": [{
        "type": "Feature", "properties": {"name": "site"},
        "geometry": {"type": "Polygon", "coordinates": [[[p["lon"], p["lat"]] for p in site + site[:1]]]}}]}),
        encoding="utf-8")
    text = (f"mission: fenced\nworld: {REPO / 'worlds' / 'campus.yaml'}\nplaces: {json.dumps(corners)}\n" + FENCES
            + "steps:\n  - go_to: goal\n")
    summary = check(tmp_path, text, "120 s")
    assert summary["status"] == "success"  # inside the yard, away from the pond: no failsafe fires
    assert not [e for e in summary["events"] if e["kind"] == "failsafe"]


def test_routes_and_places_from_files(tmp_path):
    frame = frame_of("campus.yaml")
    named = {"a": place(frame, 0, 8), "b": place(frame, 8, 8)}
    (tmp_path / "survey.gpx").write_text(
        '<?xml version="1.0"?><gpx version="1.1" creator="test" xmlns="http://www.topografix.com/GPX/1/1">'
        + "".join(f'<wpt lat="{p["lat"]}" lon="{p["lon"]}"><name>{n}</name></wpt>' for n, p in named.items())
        + "</gpx>", encoding="utf-8")
    path = [place(frame, x, y) for x, y in ((0, 4), (4, 6), (8, 4))]
    (tmp_path / "field_path.gpx").write_text(
        '<?xml version="1.0"?><gpx version="1.1" creator="test" xmlns="http://www.topografix.com/GPX/1/1"><rte>'
        + "".join(f'<rtept lat="{p["lat"]}" lon="{p["lon"]}"></rtept>' for p in path) + "</rte></gpx>",
        encoding="utf-8")
    text = f"mission: from_files\nworld: {REPO / 'worlds' / 'campus.yaml'}\n" + FILES
    summary = check(tmp_path, text, "400 s")
    assert summary["status"] == "success", summary["events"][-3:]
    assert summary["distance_m"] > 20  # the file's route, a and b, then back along the path
