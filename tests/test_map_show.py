"""``beastbt map show``: a map drawn with its places, as a PNG; warnings for places in walls; bad input exits 2."""

from __future__ import annotations

import cv2
import numpy as np

from beastbt.cli import main
from tests.map_support import OFFICE_MAP
from tests.test_map_navigation import REPO

PLACE_BGR = (0x5c, 0x25, 0xc2)  # the places' colour, #c2255c


def place_pixels(png) -> int:
    image = cv2.imread(str(png))
    assert image is not None and image.shape[0] > 200 and image.shape[1] > 300
    return int(np.count_nonzero(np.all(np.abs(image.astype(int) - PLACE_BGR) < 40, axis=2)))


def test_the_map_with_a_missions_places(tmp_path, capsys):
    bare, placed = tmp_path / "bare.png", tmp_path / "placed.png"
    assert main(["map", "show", str(OFFICE_MAP), "--out", str(bare)]) == 0
    assert main(["map", "show", str(OFFICE_MAP), "--places", str(REPO / "missions" / "office_rooms.yaml"),
                 "--out", str(placed)]) == 0
    assert "(2 places)" in capsys.readouterr().out
    assert place_pixels(bare) == 0 and place_pixels(placed) > 20
    image = cv2.imread(str(bare))
    # white free space, black walls and grey unknown all appear
    flat = image.reshape(-1, 3)
    for bgr in ((255, 255, 255), (0, 0, 0), (204, 204, 204)):
        assert np.count_nonzero(np.all(np.abs(flat.astype(int) - bgr) < 4, axis=1)) > 500, bgr


def test_a_places_file_and_a_place_in_a_wall(tmp_path, capsys):
    places = tmp_path / "rooms.yaml"
    places.write_text("kitchen: {x: 3 m, y: 5.5 m}\nwall: {x: 2.5 m, y: 0 m, tolerance: 0.3 m}\n")
    out = tmp_path / "rooms.png"
    assert main(["map", "show", str(OFFICE_MAP), "--places", str(places), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "place 'wall' (2.5, 0) m lies in an occupied cell" in err and "kitchen" not in err
    assert place_pixels(out) > 20


def test_bad_input_exits_2_with_the_position(tmp_path, capsys):
    assert main(["map", "show", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "x.png")]) == 2
    assert "none.yaml:1:1: error: file not found" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("kitchen: {x: 3 m}\n")
    assert main(["map", "show", str(OFFICE_MAP), "--places", str(bad), "--out", str(tmp_path / "y.png")]) == 2
    assert "bad.yaml:1:10: error: place 'kitchen' needs x and y" in capsys.readouterr().err
    assert not (tmp_path / "y.png").exists()


def test_a_recorded_run_on_a_map_carries_map_once_and_the_planned_path(tmp_path, monkeypatch):
    import base64
    from beastbt.mapping.occupancy_map import load_map
    from beastbt.recording.reader import find_recording, read_recording
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(REPO / "missions" / "office_rooms.yaml"), "--speed", "max", "--max-time", "4"]) == 1
    folder = next((tmp_path / "runs").iterdir())
    rec = read_recording(find_recording(folder), topics=("/map", "/path", "/map/pose"))
    maps, paths = rec.messages["/map"], rec.messages["/path"]
    assert len(maps) == 1  # latched, sent once: nothing marked the map since
    grid = maps[0][-1]
    saved = load_map(OFFICE_MAP)
    cells = np.frombuffer(base64.b64decode(grid["data"]), dtype=np.int8).reshape(-1, grid["column_count"])
    assert np.array_equal(cells, saved.data) and grid["frame_id"] == "map"
    assert grid["pose"]["position"]["x"] == saved.origin_x and grid["cell_size"]["x"] == saved.resolution_m
    import jsonschema
    from beastbt.recording.schemas import CHANNELS
    jsonschema.Draft202012Validator(CHANNELS["/map"]).validate(grid)
    for _, *rest in paths:
        jsonschema.Draft202012Validator(CHANNELS["/path"]).validate(rest[-1])
    path = paths[0][-1]["entities"][0]
    points = path["lines"][0]["points"]
    assert abs(points[0]["x"]) < 0.05 and abs(points[0]["y"]) < 0.05  # from where the robot stood (the origin)...
    assert (round(points[-1]["x"], 2), round(points[-1]["y"], 2)) == (3.0, 5.5)  # ...to the kitchen
    poses = [m[-1]["pose"]["position"] for m in rec.messages["/map/pose"]]
    assert 15 <= len(poses) <= 25  # 5 Hz over 4 s
    assert max(p["x"] for p in poses) > 0.05  # it set off toward the kitchen
    # the report draws the map with what was planned and driven on it
    from beastbt.recording.report import make_report
    report = make_report(str(folder), str(tmp_path / "report"))
    assert "saved_map" in report.plots and report.plots["saved_map"].stat().st_size > 10_000
    assert place_pixels(report.plots["saved_map"]) > 20  # the places of the summary's map_waypoints
