"""The detectors' frame entries (beastbt/vision/detection_feed.py) and their Foxglove messages, without a run.

A feed keeps what each detector found per frame, carries a slower detector's answer (the QR reader's) to the frames
of the next half second, and clears the views once when the detectors sleep; every kind becomes a valid
``foxglove.ImageAnnotations`` in the published image's pixels.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import jsonschema
import numpy as np

from beastbt.recording.detection_views import image_annotations, published_scale, tags_update
from beastbt.vision.colour import ColourBlob
from beastbt.vision.detection_feed import DetectionFeed
from beastbt.vision.fiducials import TagDetection
from beastbt.vision.motion import MotionResult
from beastbt.vision.qr_codes import QrDetection
from conftest import REPO

OFFICIAL = REPO / "tests" / "data" / "foxglove"
SQUARE = np.array([[100.0, 50.0], [140.0, 50.0], [140.0, 90.0], [100.0, 90.0]])


@dataclass
class Frame:
    """What the feed reads of a camera frame."""

    seq: int
    stamp_s: float
    image: np.ndarray


def frame(seq: int) -> Frame:
    return Frame(seq, 0.1 * seq, np.zeros((240, 320, 3), np.uint8))


def tag() -> TagDetection:
    return TagDetection("apriltag_36h11", 3, SQUARE, 0.16, np.zeros(3), np.array([0.0, 0.0, 1.2]),
                        (1.3, 0.1, 0.25), 3.1)


def validator(name: str) -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(json.loads((OFFICIAL / f"{name}.json").read_text(encoding="utf-8")))


def test_a_slower_detectors_answer_is_carried_for_half_a_second_and_the_views_are_cleared_once():
    feed = DetectionFeed()
    feed.on_result("tags:apriltag_36h11", frame(1), [tag()])
    feed.on_result("qr", frame(1), [QrDetection("door-3", SQUARE + 100)])
    feed.on_result("tags:apriltag_36h11", frame(2), [])
    [first, second] = feed.take(0.25)
    assert first["seq"] == 1 and first["tags"][0]["id"] == 3 and first["qr"][0]["text"] == "door-3"
    assert first["tags"][0]["position_m"] == [1.3, 0.1, 0.25] and first["size"] == [320, 240]
    assert second["seq"] == 2 and second["tags"] == [] and second["qr"][0]["text"] == "door-3"  # carried
    feed.on_result("tags:apriltag_36h11", frame(7), [])
    [later] = feed.take(0.75)
    assert "qr" not in later  # 0.6 s after the read: no longer shown
    assert feed.take(1.0) == []  # the detectors may still be awake
    [cleared] = feed.take(1.3)  # nothing for more than half a second: one entry without a kind
    assert cleared == {"seq": -1, "stamp_s": 1.3, "size": [320, 240]}
    assert feed.take(2.0) == []


def test_every_kind_is_a_valid_image_annotation_in_the_published_pixels():
    feed = DetectionFeed()
    f = frame(1)
    feed.on_result("tags:apriltag_36h11", f, [tag()])
    feed.on_result("qr", f, [QrDetection("door-3", SQUARE + 100)])
    feed.on_result("colour:red", f, (ColourBlob(0.02, (30.0, 40.0), (20, 30, 20, 20)), None))
    feed.on_result("motion", f, MotionResult(0.05, (200, 100, 60, 120), True, True))
    [entry] = feed.take(0.1)
    scale = published_scale(320, 160)
    assert scale == 0.5 and published_scale(320, 0) == 1.0
    msg = image_annotations(5 * 10**9, entry, scale)
    assert not list(validator("ImageAnnotations").iter_errors(msg))
    outlines = [[(p["x"], p["y"]) for p in a["points"]] for a in msg["points"]]
    assert outlines[0] == [(50.0, 25.0), (70.0, 25.0), (70.0, 45.0), (50.0, 45.0)]  # the tag, half size
    assert outlines[3] == [(100.0, 50.0), (130.0, 50.0), (130.0, 110.0), (100.0, 110.0)]  # the moving region
    assert [t["text"] for t in msg["texts"]] == ["tag 3 1.30 m", "qr door-3", "red 2.0 %", "motion 5.0 %"]
    update = tags_update(5 * 10**9, "base_link", entry)
    assert not list(validator("SceneUpdate").iter_errors(update))
    assert update["entities"][0]["cubes"][0]["pose"]["position"] == {"x": 1.3, "y": 0.1, "z": 0.25}


def test_motion_still_learning_the_scene_draws_no_box():
    feed = DetectionFeed()
    feed.on_result("motion", frame(1), MotionResult(1.0, (0, 0, 320, 240), False, False))
    [entry] = feed.take(0.1)
    assert entry["motion"]["warm"] is False
    assert image_annotations(0, entry) == {"circles": [], "points": [], "texts": []}
    assert tags_update(0, "base_link", entry) is None
