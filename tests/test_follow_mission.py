"""missions/line_to_intersection.yaml (the language doc's example) end to end through the CLI."""

from __future__ import annotations

import json
import math

import cv2
import pytest
import yaml

from beastbt import cli
from conftest import REPO

MISSION = REPO / "missions" / "line_to_intersection.yaml"
DOC = (REPO / "docs" / "mission-language.md").read_text()


def test_the_mission_is_the_doc_example_as_written():
    block = DOC.split("Follow the line to the next intersection, then turn:")[1].split("```yaml\n")[1].split("```")[0]
    assert yaml.safe_load(MISSION.read_text()) == yaml.safe_load(block)


@pytest.mark.parametrize("seed", [1, 4, 7])
def test_line_to_intersection_succeeds(tmp_path, seed):
    out = tmp_path / "s.json"
    runs = tmp_path / "runs"
    code = cli.main(["run", str(MISSION), "--seed", str(seed), "--summary", str(out), "--runs-dir", str(runs)])
    s = json.loads(out.read_text())
    assert code == 0 and s["status"] == "success"
    t = s["truth"]
    # turned left at the crossing (2, 0) and followed the branch north for 2 m
    assert abs(t["final_pose"]["x"] - 2.0) < 0.03
    assert 1.9 < t["final_pose"]["y"] < 2.1
    assert abs(math.remainder(t["final_pose"]["yaw_deg"] - 90.0, 360.0)) < 5.0
    assert t["line_within_5cm_frac"] >= 0.95 and t["line_error_p95_m"] < 0.03
    assert t["intersections_passed"] == 1 and t["intersections_detected"] == 1 and t["false_intersections"] == 0
    # the snapshot at the junction is a real JPEG of the camera's frame in the run folder
    [folder] = list(runs.iterdir())
    image = cv2.imread(str(folder / "junction.jpg"))
    assert image is not None and image.shape == (240, 320, 3)
    assert any(e["kind"] == "snapshot" and "junction.jpg" in e["text"] for e in s["events"])


def test_patrol_keeps_the_camera_off(tmp_path):
    out = tmp_path / "p.json"
    assert cli.main(["run", str(REPO / "missions" / "patrol.yaml"), "--seed", "1", "--no-record", "--summary", str(out)]) == 0
    s = json.loads(out.read_text())
    assert "camera" not in s and "line_error_p95_m" not in s["truth"]
