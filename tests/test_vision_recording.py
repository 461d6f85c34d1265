"""A recorded run keeps its photos: files in the run folder, messages on /camera/photo, attachments the report shows."""

from __future__ import annotations

import base64
import json
from pathlib import Path

import cv2
import numpy as np

from beastbt.cli import main
from beastbt.recording.reader import read_recording

ROOT = Path(__file__).resolve().parents[1]
MISSION = """mission: photos
steps:
  - look: {tilt: 40 deg}
  - photo: {name: lab}
  - alert: {text: "someone in the lab", photo: true}
"""


def test_photos_are_in_the_run_folder_on_camera_photo_and_in_the_report(tmp_path, capsys):
    mission = tmp_path / "photos.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    summary = tmp_path / "summary.json"
    code = main(["run", str(mission), "--world", str(ROOT / "worlds" / "lab.yaml"), "--runs-dir",
                 str(tmp_path / "runs"), "--summary", str(summary)])
    assert code == 0
    [folder] = list((tmp_path / "runs").iterdir())
    assert (folder / "lab.jpg").is_file() and (folder / "alert-1.jpg").is_file()
    s = json.loads(summary.read_text())
    assert [p["name"] for p in s["vision"]["photos"]] == ["lab", "alert-1"]
    assert s["alerts"][0]["text"].startswith("someone in the lab (photo ")
    rec = read_recording(folder / "run.mcap")
    photos = rec.messages.get("/camera/photo", [])
    assert len(photos) == 2
    for (_, msg), name in zip(photos, ["lab.jpg", "alert-1.jpg"]):
        data = base64.b64decode(msg["data"])
        assert data == (folder / name).read_bytes()
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape == (240, 320, 3)
    assert set(rec.attachments) >= {"lab.jpg", "alert-1.jpg"}
    assert any(e["kind"] == "alert" for e in rec.topic("/events")) or any(
        "someone in the lab" in m.get("message", "") for m in rec.topic("/log"))
    out = tmp_path / "report"
    capsys.readouterr()
    assert main(["report", str(folder), "--out", str(out)]) == 0
    said = capsys.readouterr().out.splitlines()  # the report's lines name the photos and the alert, as the run's did
    assert "  photos: 2 (lab, alert-1)" in said and any(x.startswith("  alerts: 1, the last at ") for x in said)
    html = next(out.rglob("*.html")).read_text(encoding="utf-8")
    assert "snapshot_lab.jpg" in html and "snapshot_alert-1.jpg" in html
