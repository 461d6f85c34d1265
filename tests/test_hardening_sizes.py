"""Legal but large files cost time and memory in proportion to their size, and oversized ones are refused at their
place (issue 38, points 3 and 5).

Validating a mission grows linearly with its places (4,000 took 109 s when every place was compared with every
other). The probe's inputs are generated here, never committed as big files; the ones that cost memory run the
public command line in a child under an address-space limit (``beastbt_own_rss``), so a regression fails fast
instead of eating the machine. Timings are in benchmarks/validate_scaling.py; here only ratios with generous bounds.
"""

from __future__ import annotations

import random
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from beastbt.core import yaml_source
from beastbt.core.errors import InvalidInput
from beastbt.estimation.geodesy import distance_m
from beastbt.mission import geo_files, place_neighbours, warnings
from beastbt.mission.model import load_mission
from beastbt.sim import joystick_limits
from beastbt.validate import validate_file
from conftest import REPO
from hostile_files import write_gpx as _write_gpx, write_kml as _write_kml, write_script as _write_script
from hostile_yaml import many_places
from test_hardening_input import beastbt_own_rss


def _pairwise(places: list, far_m: float) -> dict[int, tuple[float, str]]:
    """What the warnings computed before issue 38: every place against every other."""
    out = {}
    for i, p in enumerate(places):
        others = [(distance_m(p.lat, p.lon, o.lat, o.lon), o.name) for j, o in enumerate(places) if j != i]
        if others and all(d > far_m for d, _ in others):
            out[i] = min(others)
    return out


def test_lonely_places_are_those_the_pairwise_comparison_finds():
    rng = random.Random(38)
    for trial in range(40):
        places = []
        for k in range(rng.choice([2, 3, 5, 20, 60])):
            kind = rng.random()
            if kind < 0.5:  # a cluster in Madrid
                lat, lon = 40.4 + rng.uniform(-0.3, 0.3), -3.7 + rng.uniform(-0.3, 0.3)
            elif kind < 0.7:  # swapped
                lat, lon = -3.7 + rng.uniform(-0.01, 0.01), 40.4 + rng.uniform(-0.01, 0.01)
            else:  # anywhere, the poles and the antimeridian included
                lat, lon = rng.uniform(-90, 90), rng.choice([rng.uniform(-180, 180), 179.9, -179.9])
            places.append(SimpleNamespace(name=f"p{k}", lat=lat, lon=lon))
        expected = _pairwise(places, warnings.FAR_PLACE_M)
        got = place_neighbours.lonely_places(places, warnings.FAR_PLACE_M)
        assert got.keys() == expected.keys(), trial
        for i, (d, name) in expected.items():
            assert got[i][1] == name and abs(got[i][0] - d) < 1e-3 * max(1.0, d), trial


def test_many_lonely_places_are_compared_with_numpy_to_the_same_answer():
    places = [SimpleNamespace(name=f"p{i}", lat=-60 + (i % 10) * 1.2, lon=-170 + (i // 10) * 1.2) for i in range(60)]
    assert len(places) > place_neighbours.ROWS_IN_PYTHON
    got = place_neighbours.lonely_places(places, warnings.FAR_PLACE_M)
    expected = _pairwise(places, warnings.FAR_PLACE_M)
    assert got.keys() == expected.keys() and len(got) == 60
    assert all(got[i][1] == expected[i][1] and abs(got[i][0] - expected[i][0]) < 1e-3 for i in expected)


def _distance_calls(monkeypatch, count: int, far_flung: bool, tmp_path) -> int:
    path = tmp_path / f"m{count}.yaml"
    path.write_text(many_places(count, far_flung))
    mission = load_mission(path)
    calls = [0]

    def counted(*args):
        calls[0] += 1
        return distance_m(*args)

    monkeypatch.setattr(warnings, "distance_m", counted)
    monkeypatch.setattr(place_neighbours, "distance_m", counted)
    found = warnings.mission_warnings(mission)
    assert len(found) == (count if far_flung else 0)
    return calls[0]


def test_the_far_place_warnings_measure_a_number_of_distances_linear_in_the_places(monkeypatch, tmp_path):
    # Four times the places: about four times the distances (it was sixteen: every place against every other).
    few, many = (_distance_calls(monkeypatch, n, False, tmp_path) for n in (1000, 4000))
    assert many < 6 * few, (few, many)


def test_a_mission_of_4000_places_validates_in_under_8_times_the_cost_of_1000(tmp_path):
    # Processor time of this process, so a busy machine does not fail it; 16x before (6.5 s against 109 s).
    # The least of three tries of each size: a garbage collection or a neighbour's cache misses falling in one
    # try must not decide it (linear is 4x; quadratic was 16x).
    # The test process's own heap (all the tests before this one) is moved out of the collector's sight, so that
    # what is timed is the validation's work, not collections walking what earlier tests left (in CI that made
    # 4,000 places 8.7x the cost of 1,000 while alone they are 4.7x).
    import gc
    gc.collect()
    gc.freeze()
    costs: dict[int, float] = {}
    try:
        for count in (1000, 1000, 1000, 1000, 4000, 4000, 4000):  # the first 1000 loads the modules
            path = tmp_path / f"m{count}.yaml"
            path.write_text(many_places(count))
            t0 = time.process_time()
            assert validate_file(str(path)) == []
            costs[count] = min(costs.get(count, float("inf")), time.process_time() - t0)
    finally:
        gc.unfreeze()
    assert costs[4000] < 8 * costs[1000], costs


def test_a_mission_of_many_places_in_braces_is_composed_by_libyaml():
    # Counting every '{' of 4,000 places made the file look nested too deep for libyaml: PyYAML's composer took
    # it, ten times slower. The real depth is counted now; a really deep file still goes to PyYAML's composer.
    assert yaml_source._compose_fast(many_places(4000)) is not None
    assert yaml_source._compose_fast("a: " + "[" * 300 + "]" * 300 + "\n") is None
    assert yaml_source._compose_fast("a: " + "{b: " * 300 + "1" + "}" * 300 + "\n") is None


# --- route files and joystick scripts: bytes, points, events (issue 38, point 5 of its Why) ----------------------

def _route_mission(tmp_path: Path, route: str) -> Path:
    path = tmp_path / "m.yaml"
    path.write_text(f"mission: m\nsteps:\n  - route: {{file: {route}}}\n")
    return path


def _refused_cleanly(code: int, err: str, rss_mb: float) -> None:
    assert code == 2, err[-2000:]
    assert "internal error" not in err and "Traceback" not in err and "MemoryError" not in err, err[-2000:]
    assert rss_mb < 200, rss_mb


@pytest.mark.parametrize("name, write, says", [
    ("probe.gpx", _write_gpx, "MB: a route file is read up to 16 MB"),
    ("probe.kml", _write_kml, "MB: a route file is read up to 16 MB"),
])
def test_a_2_million_point_route_file_is_refused_by_its_size_at_the_key_that_names_it(tmp_path, name, write, says):
    write(tmp_path / name, 2_000_000)  # the probe's: 78 MB of GPX (here with elevations: more), 38 MB of KML
    assert (tmp_path / name).stat().st_size > 30 << 20
    code, _, err, rss = beastbt_own_rss("validate", str(_route_mission(tmp_path, name)), cwd=tmp_path)
    _refused_cleanly(code, err, rss)
    assert f"m.yaml:3:19: error: the route file '{name}' is " in err and says in err, err
    assert "hint: thin it to at most 10,000 points" in err


@pytest.mark.parametrize("name, write, line, column, what", [
    ("many.gpx", _write_gpx, 3 + 10_000, 1, "points (wpt, rtept, trkpt)"),  # the 10,001st trkpt's line
    ("many.kml", _write_kml, 3 + 1_000, 1, "coordinates (lon,lat tuples)"),  # ten a line: the 1,001st line
])
def test_a_route_file_under_the_size_cap_but_over_the_point_cap_is_refused_at_the_first_point_too_many(
        tmp_path, name, write, line, column, what):
    write(tmp_path / name, 200_000)  # within 16 MB: the points are counted as the XML streams by
    assert (tmp_path / name).stat().st_size < 16 << 20
    code, _, err, rss = beastbt_own_rss("validate", str(_route_mission(tmp_path, name)), cwd=tmp_path)
    _refused_cleanly(code, err, rss)
    assert f"{tmp_path / name}:{line}:{column}: error: more than 10,000 {what}" in err, err
    assert f"m.yaml:3:19: error: the route file {name} cannot be read" in err


def test_a_geojson_and_a_waypoints_file_over_the_point_cap_are_refused_at_their_line(tmp_path):
    pairs = ",\n".join(f"[-3.{i % 7000:04d}, 40.{i % 10000:04d}]" for i in range(20_000))
    (tmp_path / "r.geojson").write_text('{"type": "Feature", "geometry": {"type": "LineString", "coordinates": [\n'
                                        + pairs + "]}}\n")
    with pytest.raises(InvalidInput) as info:
        load_mission(_route_mission(tmp_path, "r.geojson"))
    assert f"{tmp_path / 'r.geojson'}:10002:1: error: more than 10,000 coordinate lists" in info.value.format()
    rows = "".join(f"{i}\t0\t3\t16\t0\t0\t0\t0\t40.{i % 10000:04d}\t-3.7\t0\t1\n" for i in range(1, 10_002))
    (tmp_path / "r.waypoints").write_text("QGC WPL 110\n" + rows)
    with pytest.raises(InvalidInput) as info:
        load_mission(_route_mission(tmp_path, "r.waypoints"))
    assert f"{tmp_path / 'r.waypoints'}:10002:1: error: more than 10,000 waypoints" in info.value.format()


def test_a_200000_deep_geojson_is_a_positioned_problem_not_an_internal_error(tmp_path):
    (tmp_path / "deep.geojson").write_text("[" * 200_000 + "]" * 200_000)
    code, _, err, rss = beastbt_own_rss("validate", str(_route_mission(tmp_path, "deep.geojson")), cwd=tmp_path)
    _refused_cleanly(code, err, rss)
    assert f"{tmp_path / 'deep.geojson'}:1:65: error: not valid GeoJSON: lists and objects nested more than 64 " \
           f"deep" in err, err
    assert "m.yaml:3:19: error: the route file deep.geojson cannot be read" in err


def test_a_route_file_within_its_bounds_still_gives_its_points(tmp_path):
    _write_kml(tmp_path / "ok.kml", 10_000)
    _write_gpx(tmp_path / "ok.gpx", 10_000)
    assert len(geo_files.read_points(tmp_path / "ok.kml", "route").points) == 10_000
    assert len(geo_files.read_points(tmp_path / "ok.gpx", "route").points) == 10_000


@pytest.mark.parametrize("command", [["validate"], ["run", str(REPO / "missions" / "patrol.yaml"), "--joystick"]])
def test_a_2_million_event_joystick_script_is_refused_by_its_size(tmp_path, command):
    script = tmp_path / "probe.yaml"
    _write_script(script, 2_000_000)  # the probe's 63 MB
    assert script.stat().st_size > 60_000_000
    code, _, err, rss = beastbt_own_rss(*command, str(script), cwd=tmp_path)
    _refused_cleanly(code, err, rss)
    assert f"{script}:1:1: error: the joystick script is " in err and "MB: a joystick script is read up to 8 MB" \
        in err, err
    assert "hint: a joystick script is a short list of timed events" in err


@pytest.mark.parametrize("command", [["validate"], ["run", str(REPO / "missions" / "patrol.yaml"), "--joystick"]])
def test_a_joystick_script_under_the_size_cap_but_over_the_event_cap_is_refused_at_the_first_event_too_many(
        tmp_path, command):
    script = tmp_path / "many.yaml"
    _write_script(script, 200_000)
    assert script.stat().st_size < 8 << 20
    code, _, err, rss = beastbt_own_rss(*command, str(script), cwd=tmp_path)
    _refused_cleanly(code, err, rss)
    assert f"{script}:10001:3: error: more than 10,000 events: a joystick script holds at most 10,000" in err, err


def test_a_joystick_event_of_many_values_is_refused_at_the_value_too_many():
    text = "- {at: 1 s, press: enable}\n- {at: 2 s, linear: [" + ", ".join(["0"] * 300_000) + "]}\n"
    problem = joystick_limits.text_size_problem(text, "s.yaml")
    assert problem is not None and problem.file == "s.yaml" and problem.position.line == 2
    assert problem.message.startswith("more than 200,000 values")
    assert joystick_limits.text_size_problem("- {at: 1 s, press: enable}\n" * 100, "s.yaml") is None


# --- map images: the pixels a header declares (issue 38, point 6 of its Why) ---------------------------------------

def _map_with_image(tmp_path: Path, image_name: str, image: bytes) -> Path:
    (tmp_path / image_name).write_bytes(image)
    (tmp_path / "huge.yaml").write_text(f"resolution: 0.05\nimage: {image_name}\norigin: [0, 0, 0]\n")
    (tmp_path / "m.yaml").write_text("mission: m\nmap: huge.yaml\nsteps:\n  - wait: 1 s\n")
    return tmp_path / "m.yaml"


def test_a_pgm_declared_100000_by_100000_is_refused_at_the_image_key_not_an_internal_error(tmp_path):
    mission_path = _map_with_image(tmp_path, "huge.pgm", b"P5\n# a comment\n100000 100000\n255\n" + bytes(1000))
    code, _, err, rss = beastbt_own_rss("validate", str(mission_path), cwd=tmp_path)
    _refused_cleanly(code, err, rss)
    assert f"{tmp_path / 'huge.yaml'}:2:8: error: the map image huge.pgm declares 100,000 x 100,000 pixels " \
           f"(10,000,000,000): a map holds at most 40,000,000 cells" in err, err
    assert "hint: use a coarser resolution or crop the map" in err


@pytest.mark.parametrize("name, image, says", [
    ("huge.png", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + (30_000).to_bytes(4, "big") * 2 + bytes(100),
     "declares 30,000 x 30,000 pixels"),
    ("huge.bmp", b"BM" + bytes(16) + (20_000).to_bytes(4, "little") + (-20_000).to_bytes(4, "little", signed=True)
     + bytes(100), "declares 20,000 x 20,000 pixels"),
    ("huge.jpg", b"\xff\xd8\xff\xe0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00"
     b"\xff\xc0\x00\x0b\x08" + (30_000).to_bytes(2, "big") * 2 + b"\x01\x01\x11\x00" + bytes(100),
     "declares 30,000 x 30,000 pixels"),  # within OpenCV's 2^30: it would decode 900 million pixels
    ("broken.pgm", b"P5\nwide high\n255\n", "its PGM/PPM header has no width and height"),
    ("empty.pgm", b"P5\n0 10\n255\n", "declares 0 x 10 pixels: an empty image"),
])
def test_a_map_image_header_over_the_cap_or_broken_is_refused_at_the_image_key(tmp_path, name, image, says):
    from beastbt.mapping.occupancy_map import load_map
    _map_with_image(tmp_path, name, image)
    with pytest.raises(InvalidInput) as info:
        load_map(tmp_path / "huge.yaml")
    text = info.value.format()
    assert f"{tmp_path / 'huge.yaml'}:2:8: error:" in text and says in text, text


def test_an_image_opencv_refuses_by_its_own_bound_is_a_positioned_problem(tmp_path, monkeypatch):
    # A format whose header is not read here (TIFF) declaring more than OpenCV's 2^30 pixels: its cv2.error.
    import cv2

    from beastbt.mapping.occupancy_map import load_map

    def refuses(*args, **kwargs):
        raise cv2.error("OpenCV(5.1.0) loadsave.cpp:80: error: (-215:Assertion failed) pixels <= "
                        "CV_IO_MAX_IMAGE_PIXELS in function 'validateInputImageSize'\n")

    monkeypatch.setattr(cv2, "imread", refuses)
    monkeypatch.setattr(cv2, "imdecode", refuses)  # the map image is read through the file policy, then decoded
    _map_with_image(tmp_path, "huge.tif", b"II*\x00" + bytes(100))
    with pytest.raises(InvalidInput) as info:
        load_map(tmp_path / "huge.yaml")
    text = info.value.format()
    assert f"{tmp_path / 'huge.yaml'}:2:8: error: cannot read the map image" in text and "OpenCV cannot read it" \
        in text, text


# --- MCAP records: what a record may claim (issue 38, point 6 of its Why) -----------------------------------------

def _chunks(data: bytes) -> list[int]:
    """The byte offsets of the chunk records of an MCAP file's data section."""
    offsets, pos = [], 8  # after the magic
    while pos + 9 <= len(data):
        opcode, length = data[pos], int.from_bytes(data[pos + 1:pos + 9], "little")
        if opcode == 0x06:
            offsets.append(pos)
        if opcode == 0x02:  # the footer
            break
        pos += 9 + length
    return offsets


def _crafted(tmp_path: Path, patch) -> tuple[Path, int]:
    from recording_support import shared_run
    from beastbt.recording.reader import find_recording
    data = bytearray(find_recording(shared_run("patrol")[0]).read_bytes())
    offset = _chunks(bytes(data))[1]  # the second chunk: the first one's messages are read
    patch(data, offset)
    path = tmp_path / "crafted.mcap"
    path.write_bytes(bytes(data))
    return path, offset


TERABYTE = 1 << 40


def _claim_uncompressed(data: bytearray, at: int) -> None:
    data[at + 25:at + 33] = TERABYTE.to_bytes(8, "little")  # opcode, length, start and end times, then this


def _claim_record_length(data: bytearray, at: int) -> None:
    data[at + 1:at + 9] = TERABYTE.to_bytes(8, "little")


def _claim_records_length(data: bytearray, at: int) -> None:
    compression_length = int.from_bytes(data[at + 37:at + 41], "little")
    records_at = at + 41 + compression_length
    data[records_at:records_at + 8] = TERABYTE.to_bytes(8, "little")


@pytest.mark.parametrize("patch, says", [
    (_claim_uncompressed, "claims 1,099,511,627,776 bytes uncompressed: a chunk holds at most 268,435,456"),
    (_claim_record_length, "claims"),
    (_claim_records_length, "claims 1,099,511,627,776 bytes, but the file has"),
])
def test_a_chunk_that_claims_a_terabyte_stops_the_reading_there_with_the_file_and_its_offset(tmp_path, patch, says):
    from beastbt.recording.reader import read_recording
    path, offset = _crafted(tmp_path, patch)
    rec = read_recording(path)
    assert not rec.complete and rec.stopped_because.startswith(f"crafted.mcap: the "), rec.stopped_because
    assert f"at byte {offset:,}" in rec.stopped_because and says in rec.stopped_because, rec.stopped_because
    assert rec.message_count() > 0  # what the first chunk holds is still read


def test_a_zstd_frame_that_claims_more_than_its_chunk_is_refused_before_it_is_decompressed():
    import zstandard
    from mcap.records import Chunk

    from beastbt.recording.reader import RecordClaim, _decompressed
    frame = zstandard.ZstdCompressor().compress(bytes(1 << 20))  # its header says 1 MiB
    chunk = Chunk(message_start_time=0, message_end_time=0, uncompressed_size=1000, uncompressed_crc=0,
                  compression="zstd", data=frame)
    with pytest.raises(RecordClaim, match="holds a frame of 1,048,576 bytes, more than the 1,000 it claims"):
        _decompressed(chunk, 1234)


def test_report_of_a_chunk_claiming_a_terabyte_answers_within_bounds(tmp_path):
    path, offset = _crafted(tmp_path, _claim_uncompressed)
    code, out, err, rss = beastbt_own_rss("report", str(path), "--out", str(tmp_path / "report"), cwd=tmp_path)
    assert code == 0, err[-2000:]
    assert "Traceback" not in err and "MemoryError" not in err and rss < 400, (err[-2000:], rss)
    assert f"crafted.mcap: the chunk at byte {offset:,} claims 1,099,511,627,776 bytes uncompressed" in out, out


def test_a_geojson_of_a_million_empty_lists_or_65_levels_is_refused_on_its_text(tmp_path):
    (tmp_path / "many.geojson").write_text("[" + ",\n".join(["[]"] * 1_000_000) + "]")
    with pytest.raises(InvalidInput) as info:
        load_mission(_route_mission(tmp_path, "many.geojson"))
    assert f"{tmp_path / 'many.geojson'}:50000:1: error: more than 50,000 lists and objects" in info.value.format()
    (tmp_path / "deep.geojson").write_text('{"type": "Feature", "x": ' + "[" * 65 + "]" * 65 + "}")
    with pytest.raises(InvalidInput) as info:
        load_mission(_route_mission(tmp_path, "deep.geojson"))
    assert f"{tmp_path / 'deep.geojson'}:1:89: error: not valid GeoJSON: lists and objects nested more than 64 " \
           f"deep" in info.value.format(), info.value.format()


def test_a_kml_of_a_million_elements_without_points_is_refused_while_it_streams(tmp_path):
    (tmp_path / "many.kml").write_text('<kml xmlns="http://www.opengis.net/kml/2.2"><Document>\n'
                                       + "<Folder/>\n" * 1_000_000 + "</Document></kml>\n")
    with pytest.raises(InvalidInput) as info:
        load_mission(_route_mission(tmp_path, "many.kml"))
    assert f"{tmp_path / 'many.kml'}:200000:1: error: more than 200,000 XML elements" in info.value.format(), \
        info.value.format()


def test_recover_stops_at_a_chunk_that_claims_a_terabyte_and_says_where(tmp_path):
    from beastbt.recording.recover import recover_file
    path, offset = _crafted(tmp_path, _claim_records_length)
    messages, kept, reason = recover_file(path, tmp_path / "recovered.mcap")
    assert messages > 0 and kept == offset, (messages, kept, reason)
    assert reason.startswith(f"the record at byte {offset:,} claims 1,099,511,627,776 bytes, but the file has"), \
        reason
