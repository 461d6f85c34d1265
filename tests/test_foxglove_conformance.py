"""Recorded runs against Foxglove's own schemas: what Foxglove will open, checked message by message.

Three short simulator runs (the patrol, the GPS route, a line run on the line
track) are recorded and read back with the ``mcap`` library's reader. Every
``foxglove.*`` channel must declare Foxglove's official JSON Schema (the copy
in ``tests/data/foxglove/``, from ``@foxglove/schemas`` 2.1.0, see its README),
and every one of its messages must validate against it; every timestamp is a
real date (after 2020) and equals the message's log time; the transforms on
/tf form one tree rooted at ``map`` that holds every frame the messages name;
and /gps/fix has one fix per GNSS epoch.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import jsonschema
import pytest
from mcap.reader import make_reader

from conftest import REPO
from recording_support import GPS_ROUTE, PATROL, record_run

OFFICIAL = REPO / "tests" / "data" / "foxglove"
LINE_RUN = REPO / "missions" / "line_to_intersection.yaml"
YEAR_2020_NS = 1_577_836_800 * 10**9
"""2020-01-01T00:00:00Z in Unix epoch nanoseconds."""

RUNS = {"patrol": (PATROL, 15.0), "gps_route": (GPS_ROUTE, 25.0), "line": (LINE_RUN, 12.0)}
"""Name -> (mission, --max-time in simulated seconds): short, but each one past its first GPS epochs."""


@functools.lru_cache(maxsize=None)
def official_schema(name: str) -> dict:
    """Foxglove's JSON Schema of ``foxglove.<Type>`` (the test's own copy)."""
    return json.loads((OFFICIAL / f"{name.removeprefix('foxglove.')}.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict[str, list[tuple]]:
    """Run name -> every message as (topic, schema name, schema encoding, message encoding, log time, decoded)."""
    out = {}
    for name, (mission, max_time_s) in RUNS.items():
        folder, summary = record_run(mission, tmp_path_factory.mktemp(name), seed=1, max_time_s=max_time_s)
        assert summary["recording"]["dropped"] == 0
        rows = []
        with open(Path(folder) / "run.mcap", "rb") as f:
            for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
                rows.append((channel.topic, schema.name, schema.encoding, channel.message_encoding,
                             message.log_time, json.loads(message.data), json.loads(schema.data)))
        out[name] = rows
    return out


def foxglove_rows(rows: list[tuple]) -> list[tuple]:
    return [r for r in rows if r[1].startswith("foxglove.")]


def timestamps(node) -> list[int]:
    """Every Foxglove ``time`` in a message (at any depth), as nanoseconds."""
    found = []
    if isinstance(node, dict):
        stamp = node.get("timestamp")
        if isinstance(stamp, dict) and set(stamp) == {"sec", "nsec"}:
            found.append(stamp["sec"] * 10**9 + stamp["nsec"])
        for value in node.values():
            found.extend(timestamps(value))
    elif isinstance(node, list):
        for value in node:
            found.extend(timestamps(value))
    return found


def test_every_foxglove_message_validates_against_foxglove_s_own_schema(recordings):
    seen: set[str] = set()
    for name, rows in recordings.items():
        validators: dict[str, jsonschema.Draft202012Validator] = {}
        for topic, schema_name, encoding, message_encoding, _, message, declared in foxglove_rows(rows):
            assert (encoding, message_encoding) == ("jsonschema", "json"), topic
            official = official_schema(schema_name)
            assert declared == official, f"{name} {topic}: the declared schema is not Foxglove's {schema_name}"
            check = validators.setdefault(schema_name, jsonschema.Draft202012Validator(official))
            errors = [e.message for e in check.iter_errors(message)]
            assert not errors, f"{name} {topic}: {errors[:3]}"
            seen.add(topic)
    assert {"/gps/fix", "/gps/fused", "/tf", "/odom", "/pose/fused", "/scene", "/route", "/log",
            "/camera/image", "/camera/calibration", "/camera/annotations"} <= seen


def test_log_times_and_timestamps_are_real_dates_and_agree(recordings):
    for name, rows in recordings.items():
        for topic, *_, log_time, message, _ in rows:
            assert log_time > YEAR_2020_NS, f"{name} {topic}: log time {log_time}"
            for stamp in timestamps(message):
                assert stamp == log_time, f"{name} {topic}: timestamp {stamp} is not its log time {log_time}"


def test_transforms_form_one_tree_rooted_at_map_holding_every_frame_named(recordings):
    for name, rows in recordings.items():
        parent: dict[str, str] = {}
        named: set[str] = set()
        for topic, schema_name, *_, message, _ in foxglove_rows(rows):
            if schema_name == "foxglove.FrameTransforms":
                for t in message["transforms"]:
                    child = t["child_frame_id"]
                    assert parent.setdefault(child, t["parent_frame_id"]) == t["parent_frame_id"], \
                        f"{name}: {child} has two parents"
            elif schema_name == "foxglove.SceneUpdate":
                named |= {e["frame_id"] for e in message["entities"]}
            elif "frame_id" in message:
                named.add(message["frame_id"])
            if schema_name == "foxglove.Odometry":
                named.add(message["body_frame_id"])
        assert "map" not in parent, f"{name}: map has a parent"
        for frame in set(parent) | named:
            seen = [frame]
            while seen[-1] in parent:
                seen.append(parent[seen[-1]])
                assert len(seen) <= len(parent) + 1, f"{name}: a cycle through {seen}"
            assert seen[-1] == "map", f"{name}: {frame} hangs from {seen[-1]}, not from map"
        assert {"map", "odom", "base_link", "camera_link", "camera_optical", "gps"} <= set(parent) | {"map"}


def test_one_location_fix_per_gnss_epoch(recordings):
    indoor = [m for topic, *_, m, _ in recordings["patrol"] if topic in ("/gps/fix", "/gps/fused")]
    assert indoor == []  # the corridor is indoors: the receiver never has a fix, so there is no LocationFix
    for name in ("gps_route",):
        rows = recordings[name]
        epochs = [m["time_utc"] for topic, *_, m, _ in rows if topic == "/sensors/gps"]
        fixes = [(t, m) for topic, *_, t, m, _ in rows if topic == "/gps/fix"]
        # The receiver's first GGA comes before it knows the date (no time_utc): it joins the RMC after it.
        dated = set(epochs) - {None}
        assert len(epochs) > len(dated) + 1, f"{name}: GGA and RMC of each epoch"
        assert len(fixes) == len(dated), f"{name}: {len(fixes)} fixes for {len(dated)} epochs"
        # A fix per epoch, in order: consecutive fixes are an epoch (1 s at the MTK3339's default rate) apart.
        times = [t for t, _ in fixes]
        assert all(b - a >= 0.5e9 for a, b in zip(times, times[1:])), name
        assert all(m["position_covariance_type"] == 1 and m["position_covariance"][0] > 0 for _, m in fixes)
