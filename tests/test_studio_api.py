"""The studio's HTTP API (docs/studio.md): files and saves, validation, tree, map, round-trip edits, templates, tries.

A real server on a free loopback port serves a copy of the repository's
missions and worlds; requests are raw HTTP, as a page or a script sends them.
"""

from __future__ import annotations

import difflib
import hashlib
import http.client
import json
import os
import shutil
import signal
import time
from pathlib import Path
from typing import Any, Iterator, Optional

import pytest

from beastbt.studio.server import StudioServer
from conftest import REPO

COMMENTED = """\
# yaml-language-server: $schema=../schemas/mission.schema.json
# A to B by GPS: the comments, the order and the blank lines must survive every edit.
mission: commented     # its name
world: ../worlds/campus.yaml

places:
  a: {lat: 40.41690, lon: -3.70380}   # the gate
  b: {lat: 40.41700, lon: -3.70350, tolerance: 3 m}
  # more places later

steps:
  - route: {places: [a, b]}    # there
  - say: "Route done, going home"
  # then home

failsafes:
  gps_lost: {after: 3 s, then: hold}
on_failure: teleop
"""


class Studio:
    """A studio serving ``folder`` on a free loopback port, and raw requests to it."""

    def __init__(self, folder: Path, **options: Any) -> None:
        self.folder = folder
        self.server = StudioServer(folder, "127.0.0.1", 0, **options).start()

    def request(self, method: str, path: str, body: Any = None, headers: Optional[dict] = None,
                content_type: Optional[str] = "application/json") -> tuple[int, Any]:
        """(status, JSON answer or text) of one request; ``Host`` is 127.0.0.1:PORT unless given."""
        conn = http.client.HTTPConnection("127.0.0.1", self.server.port, timeout=60)
        sent = {"Host": f"127.0.0.1:{self.server.port}", **(headers or {})}
        data = None if body is None else (body if isinstance(body, bytes) else json.dumps(body).encode())
        if data is not None and content_type is not None:
            sent["Content-Type"] = content_type
        conn.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
        for name, value in sent.items():
            conn.putheader(name, value)
        if data is not None:
            conn.putheader("Content-Length", str(len(data)))
        conn.endheaders(data)
        r = conn.getresponse()
        raw = r.read()
        conn.close()
        try:
            return r.status, json.loads(raw)
        except ValueError:
            return r.status, raw.decode(errors="replace")

    def get(self, path: str) -> tuple[int, Any]:
        return self.request("GET", path)

    def post(self, path: str, body: Any) -> tuple[int, Any]:
        return self.request("POST", path, body)

    def put(self, path: str, body: Any) -> tuple[int, Any]:
        return self.request("PUT", path, body)


@pytest.fixture(scope="module")
def studio(tmp_path_factory) -> Iterator[Studio]:
    """The studio on a copy of missions/ and worlds/ (the missions' ``../worlds/`` resolve as in the repository)."""
    root = tmp_path_factory.mktemp("studio")
    shutil.copytree(REPO / "missions", root / "missions")
    shutil.copytree(REPO / "worlds", root / "worlds", ignore=shutil.ignore_patterns("__init__.py", "__pycache__"))
    shutil.copytree(REPO / "maps", root / "maps")
    (root / "missions" / "commented.yaml").write_text(COMMENTED, encoding="utf-8")
    s = Studio(root)
    yield s
    s.server.close()


def applied(text: str, change: dict) -> str:
    """``text`` with an edit's ``change`` (1-based line and column, end exclusive) applied, as an editor would."""
    lines = text.split("\n")

    def offset(line: int, column: int) -> int:
        return sum(len(x) + 1 for x in lines[:line - 1]) + column - 1

    return text[:offset(change["line"], change["column"])] + change["text"] + \
        text[offset(change["end_line"], change["end_column"]):]


def only_inserted(before: str, after: str) -> list[str]:
    """The lines ``after`` adds to ``before`` (without their line ends); fails when any line of ``before`` was changed
    or removed."""
    diff = list(difflib.ndiff(before.splitlines(), after.splitlines()))
    removed = [d for d in diff if d.startswith("- ")]
    assert not removed, f"lines changed or removed: {removed}"
    return [d[2:] for d in diff if d.startswith("+ ")]


def test_the_page_reads_the_schemas_validation_uses(studio):
    for name in ("mission.schema.json", "parts/lidar.schema.json"):
        status, served = studio.get(f"/schemas/{name}")
        assert status == 200, served
        assert served == json.loads((REPO / "schemas" / name).read_text(encoding="utf-8"))
    for bad in ("../pyproject.toml", "parts/../../README.md", "mission.json", "other/x.schema.json"):
        status, _ = studio.get(f"/schemas/{bad}")
        assert status == 404, bad


def test_the_folder_lists_missions_worlds_by_kind_and_reads_with_a_content_version(studio):
    status, answer = studio.get("/api/files")
    assert status == 200
    kinds = {f["path"]: f["kind"] for f in answer["files"]}
    assert kinds["missions/patrol.yaml"] == "mission" and kinds["worlds/campus.yaml"] == "world"
    assert "missions/joystick/teleop_demo.yaml" in kinds  # nested folders are walked
    status, file = studio.get("/api/files/missions/commented.yaml")
    assert status == 200 and file["text"] == COMMENTED and file["kind"] == "mission"
    assert file["version"] == hashlib.sha256(COMMENTED.encode()).hexdigest()
    assert studio.get("/api/files/missions/nothing.yaml")[0] == 404


def test_a_map_edit_and_a_text_edit_round_trip_keeping_the_rest_byte_for_byte(studio):
    path = studio.folder / "missions" / "commented.yaml"
    _, file = studio.get("/api/files/missions/commented.yaml")
    # map: add a place, then move another; every other line stays as it was
    status, added = studio.post("/api/edit", {"text": file["text"], "edit": {"op": "add_place", "lat": 40.4171234567,
                                                                             "lon": -3.7031}})
    assert status == 200 and added["name"] == "c"
    assert only_inserted(COMMENTED, added["text"]) == ["  c: {lat: 40.4171235, lon: -3.7031}"]
    assert added["text"].index("  c: ") < added["text"].index("  # more places later")  # kept after the places
    status, moved = studio.post("/api/edit", {"text": added["text"], "edit": {"op": "move_place", "name": "b",
                                                                              "lat": 40.417, "lon": -3.7036}})
    assert status == 200 and applied(added["text"], moved["change"]) == moved["text"]
    assert applied(COMMENTED, added["change"]) == added["text"]  # one replacement the editor can undo
    changed = [(a, b) for a, b in zip(added["text"].splitlines(), moved["text"].splitlines()) if a != b]
    assert changed == [("  b: {lat: 40.41700, lon: -3.70350, tolerance: 3 m}",
                        "  b: {lat: 40.417, lon: -3.7036, tolerance: 3 m}")]
    status, routed = studio.post("/api/edit", {"text": moved["text"], "edit": {"op": "add_route",
                                                                               "places": ["a", "c", "b"]}})
    assert status == 200 and only_inserted(moved["text"], routed["text"]) == ["  - route: {places: [a, c, b]}"]
    assert routed["text"].index("route: {places: [a, c, b]}") < routed["text"].index("  # then home")
    status, fenced = studio.post("/api/edit", {"text": routed["text"], "edit": {
        "op": "add_fence", "keep": "out", "polygon": [[40.4172, -3.704], [40.41725, -3.704], [40.41725, -3.70395]]}})
    assert status == 200
    new = only_inserted(routed["text"], fenced["text"])
    assert "  keepout: {fence: keepout1, then: stop}" in new and "    keep: out" in new
    assert studio.post("/api/validate", {"text": fenced["text"], "path": "missions/commented.yaml"})[1] == \
        {"problems": []}
    # save it, then a text edit: the file on disk is what was sent, byte for byte
    status, saved = studio.put("/api/files/missions/commented.yaml", {"text": fenced["text"],
                                                                      "version": file["version"]})
    assert status == 200 and path.read_text(encoding="utf-8") == fenced["text"]
    assert (path.parent / "commented.yaml.bak").read_text(encoding="utf-8") == COMMENTED
    typed = fenced["text"].replace("say: \"Route done, going home\"", "say: \"Done, going home\"")
    status, again = studio.put("/api/files/missions/commented.yaml", {"text": typed, "version": saved["version"]})
    assert status == 200 and path.read_bytes() == typed.encode()
    assert studio.get("/api/files/missions/commented.yaml")[1]["version"] == again["version"]
    path.write_text(COMMENTED, encoding="utf-8")


MIXED = ("---\r\nmission: mixed   # CRLF line ends, a document start, 4-space places, 'steps:' items\r\n"
         "places:\r\n    a: {lat: 40.4169, lon: -3.7038}   # the gate\r\n\r\n"
         "steps:\r\n- say: hi\r\n- repeat:\r\n    times: 2\r\n    steps:\r\n      - wait: 1 s\r\n"
         "failsafes:\r\n  gps_lost: {after: 3 s, then: hold}")


def test_a_file_in_its_own_style_keeps_it_through_map_edits(studio):
    text = MIXED
    for edit in ({"op": "add_place", "lat": 40.417, "lon": -3.7035}, {"op": "add_route", "places": ["a", "b"]},
                 {"op": "add_fence", "name": "pond", "keep": "out",
                  "polygon": [[40.4172, -3.704], [40.41725, -3.704], [40.41725, -3.70395]]}):
        status, answer = studio.post("/api/edit", {"text": text, "edit": edit})
        assert status == 200, answer
        assert applied(text, answer["change"]) == answer["text"]
        text = answer["text"]
    assert only_inserted(MIXED, text) and "\r\n" in text and "\n" not in text.replace("\r\n", "")
    assert not text.endswith("\n")  # it had no line end at the end, and still has none
    lines = text.split("\r\n")
    assert "    b: {lat: 40.417, lon: -3.7035}" in lines and "- route: {places: [a, b]}" in lines
    assert studio.post("/api/validate", {"text": text, "path": "missions/mixed.yaml"})[1] == {"problems": []}


def test_a_stale_save_is_a_conflict_and_nothing_is_overwritten(studio):
    path = studio.folder / "missions" / "stale.yaml"
    path.write_text("mission: stale\nsteps:\n  - wait: 1 s\n", encoding="utf-8")
    _, file = studio.get("/api/files/missions/stale.yaml")
    path.write_text("mission: stale\nsteps:\n  - wait: 2 s   # changed by someone else\n", encoding="utf-8")
    status, answer = studio.put("/api/files/missions/stale.yaml", {"text": "mission: mine\nsteps: []\n",
                                                                   "version": file["version"]})
    assert status == 409 and "changed on disk" in answer["error"]
    assert answer["disk_text"] == path.read_text(encoding="utf-8")
    assert "someone else" in path.read_text(encoding="utf-8") and not (path.parent / "stale.yaml.bak").exists()
    # a new file: version null creates it, and only once
    status, created = studio.put("/api/files/missions/new/first.yaml", {"text": "mission: first\nsteps: []\n",
                                                                        "version": None})
    assert status == 200 and (studio.folder / "missions" / "new" / "first.yaml").is_file()
    status, answer = studio.put("/api/files/missions/new/first.yaml", {"text": "mission: other\n", "version": None})
    assert status == 409 and answer["disk_text"] == "mission: first\nsteps: []\n"
    assert studio.put("/api/files/missions/x.yaml", {"text": "mission: x\n"})[0] == 400  # no version: refused


def test_paths_that_lead_out_of_the_folder_are_refused(studio, tmp_path):
    secret = tmp_path / "secret.yaml"
    secret.write_text("mission: secret\nsteps: []\n", encoding="utf-8")
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "other.yaml").write_text("mission: other\nsteps: []\n", encoding="utf-8")
    os.symlink(secret, studio.folder / "missions" / "link.yaml")
    os.symlink(outside, studio.folder / "missions" / "linkdir")
    try:
        for path in ("/api/files/..%2F..%2Fsecret.yaml", "/api/files/missions/..%2F..%2Fsecret.yaml",
                     "/api/files/%2Fetc%2Fpasswd", "/api/files/missions/link.yaml",
                     "/api/files/missions/linkdir/other.yaml"):
            status, answer = studio.get(path)
            assert status == 403 and "mission: " not in json.dumps(answer) and "text" not in answer, path
        status, _ = studio.get("/api/files/../../secret.yaml")  # unencoded: never reaches a file outside
        assert 400 <= status < 500
        for path in ("/api/files/missions/link.yaml", "/api/files/missions/linkdir/new.yaml",
                     "/api/files/..%2Fescape.yaml"):
            status, _ = studio.put(path, {"text": "mission: pwned\nsteps: []\n", "version": None})
            assert status == 403, path
        assert secret.read_text(encoding="utf-8") == "mission: secret\nsteps: []\n"
        assert not (outside / "new.yaml").exists() and not (studio.folder.parent / "escape.yaml").exists()
        listed = [f["path"] for f in studio.get("/api/files")[1]["files"]]
        assert "missions/link.yaml" not in listed and not any(p.startswith("missions/linkdir") for p in listed)
        assert studio.post("/api/validate", {"text": "mission: x\nsteps: []\n", "path": "../x.yaml"})[0] == 403
    finally:
        os.unlink(studio.folder / "missions" / "link.yaml")
        os.unlink(studio.folder / "missions" / "linkdir")


def test_a_typo_is_a_problem_at_its_line_and_column_with_a_did_you_mean(studio):
    text = "mission: typo\nworld: ../worlds/campus.yaml\nsteps:\n  - say: hello\n  - drvie: {distance: 1 m}\n"
    status, answer = studio.post("/api/validate", {"text": text, "path": "missions/typo.yaml"})
    assert status == 200
    [problem] = answer["problems"]
    assert (problem["severity"], problem["line"], problem["column"]) == ("error", 5, 5)
    assert "did you mean 'drive'" in problem["message"] and (problem["end_line"], problem["end_column"]) == (5, 10)
    # a speed above the robot's top speed is a warning, for the robot chosen
    fast = "mission: fast\nsteps:\n  - drive: {distance: 1 m, speed: 2 m/s}\n"
    warned = studio.post("/api/validate", {"text": fast})[1]["problems"]
    assert [(p["severity"], p["line"]) for p in warned] == [("warning", 3)] and "robot 'sim'" in warned[0]["message"]
    # the world a mission names resolves from the path it is saved at
    assert studio.post("/api/validate", {"text": text.replace("drvie", "drive"), "path": "missions/t.yaml"})[1] == \
        {"problems": []}
    elsewhere = studio.post("/api/validate", {"text": text.replace("drvie", "drive"), "path": "t.yaml"})[1]
    # a world, a robot profile and a joystick script are checked as what they are
    for path, typo, says in (("worlds/campus.yaml", ("datum:", "datun:"), "did you mean 'datum'"),
                             ("missions/joystick/teleop_demo.yaml", ("press: enable", "pres: enable"),
                              "did you mean 'press'")):
        right = (REPO / path).read_text(encoding="utf-8")
        assert studio.post("/api/validate", {"text": right, "path": path})[1] == {"problems": []}, path
        wrong = studio.post("/api/validate", {"text": right.replace(*typo, 1), "path": path})[1]["problems"]
        assert says in wrong[0]["message"] and "file" not in wrong[0], wrong
    [here] = elsewhere["problems"]  # ../worlds climbs out of the folder from its top: said at 'world:', not read
    assert "file" not in here and here["line"] == 2 and "world file '../worlds/campus.yaml'" in here["message"]
    assert "climbs out of the studio's folder" in here["message"]


def test_every_template_validates_and_saves(studio):
    status, answer = studio.get("/api/templates")
    names = [t["name"] for t in answer["templates"]]
    assert status == 200 and names == ["patrol", "gps_route", "line", "teleop"]
    for name in names:
        status, made = studio.post(f"/api/templates/{name}", {"path": f"missions/new_{name}.yaml"})
        assert status == 200 and made["text"].startswith("#")
        assert f"mission: new_{name}" in made["text"]
        assert studio.post("/api/validate", {"text": made["text"], "path": f"missions/new_{name}.yaml"})[1] == \
            {"problems": []}, name
    assert studio.post("/api/templates/patrl", {})[1]["error"].startswith("no template 'patrl'; did you mean")


def test_tree_nodes_carry_the_position_of_their_step(studio):
    text = (REPO / "missions" / "gps_route.yaml").read_text(encoding="utf-8")
    status, tree = studio.post("/api/tree", {"text": text, "path": "missions/gps_route.yaml"})
    assert status == 200 and tree["problems"] == [] and tree["root"] == "0"
    lines = text.splitlines()
    by_name = {n["name"]: n for n in tree["nodes"]}
    route = by_name["route a -> b -> c"]
    assert lines[route["line"] - 1][route["column"] - 1:].startswith("route:")
    say = next(n for n in tree["nodes"] if n["name"].startswith("say"))
    assert lines[say["line"] - 1][say["column"] - 1:].startswith("say:")
    go_tos = [n for n in tree["nodes"] if n["name"].startswith("go_to")]
    assert len(go_tos) == 3 and all((n["line"], n["column"]) == (route["line"], route["column"]) for n in go_tos)
    ids = {n["id"] for n in tree["nodes"]}
    assert all(parent in ids and child in ids for parent, child in tree["edges"])
    assert [route["id"], go_tos[0]["id"]] in tree["edges"]
    broken = studio.post("/api/tree", {"text": text.replace("route:", "rout:")})[1]
    assert broken["nodes"] == [] and broken["problems"][0]["line"] == 11


def test_the_map_draws_places_fences_routes_and_the_world(studio):
    _, added = studio.post("/api/edit", {"text": COMMENTED, "edit": {
        "op": "add_fence", "name": "pond", "keep": "out",
        "polygon": [[40.4172, -3.704], [40.41725, -3.704], [40.41725, -3.70395]]}})
    status, drawn = studio.post("/api/map", {"text": added["text"], "path": "missions/commented.yaml"})
    assert status == 200 and drawn["frame"] == "gps" and drawn["datum"] == {"lat": 40.4168, "lon": -3.7038}
    assert [(p["name"], p["lat"], p["lon"], p["line"]) for p in drawn["places"]] == [
        ("a", 40.4169, -3.7038, 7), ("b", 40.417, -3.7035, 8)]
    [fence] = drawn["fences"]
    assert fence["name"] == "pond" and fence["keep"] == "out" and fence["polygon"][0] == [40.4172, -3.704]
    [route] = drawn["routes"]
    assert route["places"] == ["a", "b"] and route["points"] == [[40.4169, -3.7038], [40.417, -3.7035]]
    assert drawn["world"]["name"] == "campus" and "start" in drawn["world"]
    # a world file's text is drawn as it is in the editor, unsaved changes included
    campus = (REPO / "worlds" / "campus.yaml").read_text(encoding="utf-8")
    moved = campus.replace("datum: {lat: 40.41680, lon: -3.70380", "datum: {lat: 40.5, lon: -3.6")
    world = studio.post("/api/map", {"text": moved, "path": "worlds/campus.yaml"})[1]
    assert world["datum"] == {"lat": 40.5, "lon": -3.6} and world["world"]["name"] == "campus"
    assert world["places"] == [] and world["problems"] == []
    # a text with an error still draws what it can read
    typo = studio.post("/api/map", {"text": COMMENTED.replace("say:", "sya:")})[1]
    assert [p["name"] for p in typo["places"]] == ["a", "b"] and typo["problems"]


OFFICE = "missions/office_rooms.yaml"


def _office(studio: Studio) -> str:
    return (studio.folder / OFFICE).read_text(encoding="utf-8")


def test_a_mission_on_a_map_is_drawn_in_the_map_frame_with_its_grid_and_the_world_moved_onto_it(studio):
    import base64

    import cv2
    import numpy as np

    from beastbt.mapping.occupancy_map import load_map
    from beastbt.sim.world import load_world
    text = _office(studio)
    status, drawn = studio.post("/api/map", {"text": text, "path": OFFICE})
    assert status == 200 and drawn["frame"] == "map" and drawn["problems"] == []
    assert [(p["name"], p["x"], p["y"], p["line"]) for p in drawn["places"]] == [
        ("kitchen", 3.0, 5.5, 12), ("lab", 6.0, 0.5, 13)]
    assert not any(p.get("readonly") for p in drawn["places"])
    grid = load_map(studio.folder / "maps" / "office.yaml")
    shown = drawn["map"]
    assert shown["file"] == "maps/office.yaml" and shown["resolution_m"] == grid.resolution_m
    assert shown["bounds"] == [[grid.origin_x, grid.origin_y],
                               [grid.origin_x + grid.width_m, grid.origin_y + grid.height_m]]
    head, data = shown["image"].split(",", 1)
    assert head == "data:image/png;base64"
    image = cv2.imdecode(np.frombuffer(base64.b64decode(data), np.uint8), cv2.IMREAD_UNCHANGED)
    assert image.shape == (grid.rows, grid.cols)
    assert ((image[::-1] == 0) == grid.occupied()).all()  # top row first, occupied black
    # the world's walls in the map frame: the world's start (2.5, 2.0, facing east) is the map's origin here
    world = load_world(str(studio.folder / "worlds" / "office.yaml"))
    sx, sy = world.start_x, world.start_y
    assert drawn["world"]["walls"][0] == [w - o for w, o in zip(
        [world.walls[0].x1, world.walls[0].y1, world.walls[0].x2, world.walls[0].y2], [sx, sy, sx, sy])]
    assert drawn["world"]["start"] == {"x": 0.0, "y": 0.0, "yaw_deg": 0.0}
    # a mission that starts elsewhere on the map, turned: the world turns and moves with it
    turned = text.replace("places:\n", "start: {x: 1 m, y: 2 m, yaw: 90 deg}\nplaces:\n", 1)
    drawn = studio.post("/api/map", {"text": turned, "path": OFFICE})[1]
    assert drawn["start"] == {"x": 1.0, "y": 2.0, "yaw_deg": 90.0}
    x1, y1 = world.walls[0].x1 - sx, world.walls[0].y1 - sy  # (-2.5, -2.0) from the start, turned by 90 deg
    assert drawn["world"]["walls"][0][:2] == pytest.approx([1.0 - y1, 2.0 + x1])
    # the walls drawn lie on the map's occupied cells (the map was built in this world)
    walls = np.array(studio.post("/api/map", {"text": text, "path": OFFICE})[1]["world"]["walls"])
    mids = (walls[:, :2] + walls[:, 2:]) / 2
    near = [grid.occupied()[max(0, r - 2):r + 3, max(0, c - 2):c + 3].any()
            for c, r in zip(*grid.to_cells(mids[:, 0], mids[:, 1]))]
    assert sum(near) >= len(near) - 1
    # a typo elsewhere does not blank the map while it is typed: the grid, the walls and the places stay
    typo = studio.post("/api/map", {"text": text.replace("go_to: lab", "go_too: lab"), "path": OFFICE})[1]
    assert typo["problems"] and typo["frame"] == "map" and typo["map"]["bounds"] == shown["bounds"]
    assert typo["world"]["walls"] == walls.tolist()
    assert [(p["name"], p["x"], p["y"]) for p in typo["places"]] == [("kitchen", 3.0, 5.5), ("lab", 6.0, 0.5)]


def test_places_from_a_file_are_drawn_read_only_and_the_map_cannot_edit_them(studio):
    (studio.folder / "missions" / "rooms.yaml").write_text("kitchen: {x: 3.0 m, y: 5.5 m}\nlab: {x: 6 m, y: 0.5 m, "
                                                           "yaw: 90 deg}\n", encoding="utf-8")
    text = _office(studio)
    start = text.index("places:")
    end = text.index("steps:")
    from_file = text[:start] + "places: {file: rooms.yaml}\n" + text[end:]
    drawn = studio.post("/api/map", {"text": from_file, "path": OFFICE})[1]
    assert drawn["problems"] == []
    assert [(p["name"], p["x"], p["y"], p["yaw_deg"], p["readonly"], p["file"]) for p in drawn["places"]] == [
        ("kitchen", 3.0, 5.5, None, True, "rooms.yaml"), ("lab", 6.0, 0.5, 90.0, True, "rooms.yaml")]
    status, refused = studio.post("/api/edit", {"text": from_file, "edit": {"op": "add_place", "x": 1, "y": 1}})
    assert status == 400 and "rooms.yaml" in refused["error"] and refused["line"] == from_file[:start].count(
        "\n") + 1


def test_places_on_a_map_are_added_and_moved_in_metres_keeping_the_rest_byte_for_byte(studio):
    text = _office(studio)
    status, added = studio.post("/api/edit", {"text": text, "edit": {"op": "add_place", "x": 3.254, "y": -1.5}})
    assert status == 200 and added["name"] == "a"
    assert only_inserted(text, added["text"]) == ["  a: {x: 3.25 m, y: -1.5 m}"]
    assert applied(text, added["change"]) == added["text"]
    status, moved = studio.post("/api/edit", {"text": added["text"], "edit": {
        "op": "move_place", "name": "kitchen", "x": 2.5, "y": 6.456, "yaw": 90}})
    assert status == 200
    before, after = added["text"].splitlines(), moved["text"].splitlines()
    changed = [(a, b) for a, b in zip(before, after) if a != b]
    assert len(before) == len(after) and changed == [(
        "  kitchen: {x: 3.0 m, y: 5.5 m}        # north of the corridor, through the office's and the kitchen's doors",
        "  kitchen: {x: 2.5 m, y: 6.46 m, yaw: 90.0 deg} # north of the corridor, through the office's and the "
        "kitchen's doors")]  # the comment kept, pushed along by the longer place
    status, routed = studio.post("/api/edit", {"text": moved["text"], "edit": {"op": "add_route",
                                                                               "places": ["a", "kitchen", "lab"]}})
    assert status == 200 and only_inserted(moved["text"], routed["text"]) == ["  - route: {places: [a, kitchen, lab]}"]
    drawn = studio.post("/api/map", {"text": routed["text"], "path": OFFICE})[1]
    assert drawn["problems"] == []
    assert {p["name"]: (p["x"], p["y"], p["yaw_deg"]) for p in drawn["places"]} == {
        "kitchen": (2.5, 6.46, 90.0), "lab": (6.0, 0.5, None), "a": (3.25, -1.5, None)}
    [route] = drawn["routes"]
    assert route["points"] == [[3.25, -1.5], [2.5, 6.46], [6.0, 0.5]]
    assert studio.post("/api/validate", {"text": routed["text"], "path": OFFICE})[1]["problems"] == []


def test_an_edit_in_the_other_frame_is_refused_with_a_reason(studio):
    office = _office(studio)
    for edit in ({"op": "add_place", "lat": 40.4, "lon": -3.7}, {"op": "move_place", "name": "lab", "lat": 40.4,
                                                                   "lon": -3.7}):
        status, refused = studio.post("/api/edit", {"text": office, "edit": edit})
        assert status == 400 and "on a map" in refused["error"] and "x and y" in refused["error"]
        assert refused["line"] == 10  # at map:
    status, refused = studio.post("/api/edit", {"text": COMMENTED, "edit": {"op": "add_place", "x": 1, "y": 2}})
    assert status == 400 and "no 'map:'" in refused["error"] and "lat" in refused["error"]
    status, refused = studio.post("/api/edit", {"text": office, "edit": {"op": "add_place", "x": "3 m", "y": 2}})
    assert status == 400 and "'x' must be a number of metres" in refused["error"]


def test_the_guard_refuses_other_hosts_pages_and_forms(studio):
    assert studio.request("GET", "/api/files", headers={"Host": "evil.example:8070"})[0] == 403
    text = {"text": "mission: x\nsteps: []\n", "version": None}
    status, _ = studio.request("PUT", "/api/files/missions/evil.yaml", text, headers={"Origin": "http://evil.example"})
    assert status == 403
    status, _ = studio.request("PUT", "/api/files/missions/evil.yaml", text, content_type="text/plain")
    assert status == 403 and not (studio.folder / "missions" / "evil.yaml").exists()
    status, answer = studio.request("POST", "/api/validate", b"{not json")
    assert status == 400 and "not JSON" in answer["error"]
    port = studio.server.port
    same = studio.post("/api/validate", {"text": "mission: x\nsteps: []\n"})
    assert same[0] == 200
    assert studio.request("GET", "/api/files", headers={"Origin": f"http://127.0.0.1:{port}"})[0] == 200


def test_with_a_token_every_request_needs_it(tmp_path):
    (tmp_path / "m.yaml").write_text("mission: m\nsteps: []\n", encoding="utf-8")
    s = Studio(tmp_path, require_token=True)
    try:
        assert s.get("/api/files")[0] == 401 and s.get("/")[0] == 401
        token = s.server.guard.token
        assert s.server.url.endswith(f"?token={token}")
        status, answer = s.request("GET", "/api/files", headers={"Authorization": f"Bearer {token}"})
        assert status == 200 and [f["path"] for f in answer["files"]] == ["m.yaml"]
    finally:
        s.server.close()


def test_a_running_try_shows_its_console_through_the_studio_and_stops(studio):
    text = "mission: long_try\nsteps:\n  - say: waiting\n  - wait: 120 s\n"
    # As under 'beastbt studio &' in a script: the studio's process, and so its tries, have SIGINT ignored; the
    # studio's stop must end the try all the same (not kill it, which leaves no summary)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        status, started = studio.post("/api/try", {"text": text, "speed": "realtime"})
    finally:
        signal.signal(signal.SIGINT, previous)
    assert status == 200
    run_id = started["run_id"]
    deadline = time.monotonic() + 60
    status, state = studio.get(f"/api/try/{run_id}/console/api/state")
    while status != 200 and time.monotonic() < deadline:
        time.sleep(0.3)
        status, state = studio.get(f"/api/try/{run_id}/console/api/state")
    assert status == 200 and state["mission"] == "long_try"
    tree = studio.post("/api/tree", {"text": text})[1]
    # the console's node ids are the tree's: a try's live statuses can be painted on the studio's graph
    assert {n["id"]: n["name"] for n in tree["nodes"]}.items() <= {n["id"]: n["name"] for n in state["tree"]}.items()
    assert studio.post(f"/api/try/{run_id}/console/api/pause", {})[0] == 200
    assert studio.get(f"/api/try/{run_id}/console/api/nothing")[0] == 404
    status, ended = studio.post(f"/api/try/{run_id}/stop", {})
    assert status == 200 and ended["state"] == "ended" and ended["exit_code"] == 1
    assert ended["summary"]["status"] == "stopped"
    assert any("interrupted" in e["text"] for e in ended["summary"]["events"])


def test_a_first_mission_from_a_template_by_the_api_alone_runs_to_success_and_saves(studio):
    """What the page does for the non-programmer test: template, three places, a route, a keep-out fence, a try,
    a save; the saved file validates and keeps the template's comments."""
    path = "missions/first_route.yaml"
    text = studio.post("/api/templates/gps_route", {"path": path})[1]["text"]
    comments = [line for line in text.splitlines() if line.lstrip().startswith("#")]
    north, east = 1 / 111_320, 1 / 84_860  # degrees per metre at the campus datum
    for dn, de in ((5, 0), (5, 5), (0, 5)):
        text = studio.post("/api/edit", {"text": text, "edit": {"op": "add_place", "lat": 40.4168 + dn * north,
                                                                "lon": -3.7038 + de * east}})[1]["text"]
    text = studio.post("/api/edit", {"text": text, "edit": {"op": "add_route", "places": ["a", "b", "c"]}})[1]["text"]
    pond = [[40.4168 - 30 * north, -3.7038], [40.4168 - 30 * north, -3.7038 + 10 * east],
            [40.4168 - 40 * north, -3.7038 + 10 * east]]
    text = studio.post("/api/edit", {"text": text, "edit": {"op": "add_fence", "keep": "out",
                                                            "polygon": pond}})[1]["text"]
    assert studio.post("/api/validate", {"text": text, "path": path})[1] == {"problems": []}
    run_id = studio.post("/api/try", {"text": text, "path": path, "speed": "max"})[1]["run_id"]
    deadline = time.monotonic() + 180
    state = studio.get(f"/api/try/{run_id}")[1]
    while state["state"] == "running" and time.monotonic() < deadline:
        time.sleep(0.5)
        state = studio.get(f"/api/try/{run_id}")[1]
    assert state.get("exit_code") == 0, state["output"]
    assert state["summary"]["status"] == "success" and state["summary"]["mission"] == "first_route"
    assert [w["name"] for w in state["summary"]["waypoints"] if w["reached"]] == ["a", "b", "c"]
    assert state["report"] == f"/api/try/{run_id}/report/"
    assert not list((studio.folder / "missions").glob(".first_route.try-*"))  # the hidden copy is gone
    assert studio.get(f"/api/try/{run_id}/console/api/state")[0] == 409  # its console has closed
    assert studio.get("/api/try/nope")[0] == 404
    assert studio.post("/api/try", {"text": text, "speed": "fast"})[0] == 400
    status, saved = studio.put(f"/api/files/{path}", {"text": text, "version": None})
    assert status == 200
    on_disk = (studio.folder / path).read_text(encoding="utf-8")
    assert on_disk == text and all(line in on_disk.splitlines() for line in comments)
    assert studio.post("/api/validate", {"text": on_disk, "path": path})[1] == {"problems": []}


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            if int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
        except (OSError, ValueError, IndexError):
            continue
    return found


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, ended but not yet waited for, has ended)."""
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def test_the_command_prints_the_address_serves_and_its_tries_end_with_it(tmp_path):
    import subprocess
    import sys
    env = dict(os.environ, PYTHONPATH=str(REPO))
    bad = subprocess.run([sys.executable, "-m", "beastbt", "studio", str(tmp_path / "none")], capture_output=True,
                         text=True, timeout=60, env=env)
    assert bad.returncode == 2 and "is not a folder" in bad.stderr
    (tmp_path / "m.yaml").write_text("mission: m\nsteps: []\n", encoding="utf-8")
    proc = subprocess.Popen([sys.executable, "-m", "beastbt", "studio", str(tmp_path), "--listen", "127.0.0.1:0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    tries: list[int] = []
    try:
        assert proc.stdout is not None
        lines = [proc.stdout.readline() for _ in range(2)]
        url = lines[1].split()[-1]
        assert lines[1].startswith("open http://127.0.0.1:") and url.endswith("/")
        port = int(url.rsplit(":", 1)[1].strip("/"))
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        conn.request("GET", "/api/files")
        answer = json.loads(conn.getresponse().read())
        assert [f["path"] for f in answer["files"]] == ["m.yaml"]
        conn.request("GET", "/")
        page = conn.getresponse()
        assert page.status == 200 and page.getheader("Content-Type").startswith("text/html") and page.read()
        body = json.dumps({"text": "mission: long\nsteps:\n  - wait: 300 s\n", "speed": "realtime"})
        conn.request("POST", "/api/try", body=body, headers={"Content-Type": "application/json"})
        assert conn.getresponse().status == 200
        conn.close()
        tries = _children(proc.pid)
        assert tries  # the try's beastbt run
    finally:
        proc.terminate()  # SIGTERM, as a service manager ends it: the studio stops, and its tries with it
        assert proc.wait(30) == 0
    assert not [pid for pid in tries if _alive(pid)], "a try outlived the studio"
    assert not list(tmp_path.glob(".*.try-*"))  # and its hidden copy is gone
