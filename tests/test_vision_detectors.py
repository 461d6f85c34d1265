"""The camera's detectors (fiducials, QR codes, motion, colour) on clean renders and on photo-like images.

The photo-like images come from tests/photo_like.py: a perspective (the sheet turned away), blur,
sensor noise, uneven light and JPEG at quality 60.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from beastbt.vision.colour import ColourFinder, ColourRange
from beastbt.vision.fiducials import FiducialDetector, marker_image
from beastbt.vision.motion import MotionDetector
from beastbt.vision.qr_codes import QrReader
from photo_like import CAMERA, CLEAN, PHOTO, degrade, scene, tag_at

HOW = {"clean": CLEAN, "photo": PHOTO}


def _angle_error_deg(a: float, b: float) -> float:
    return abs(math.degrees(math.remainder(a - b, 2 * math.pi)))


@pytest.mark.parametrize("how", ["clean", "photo"])
@pytest.mark.parametrize("ahead, left, turned", [(0.4, 0.0, 0.0), (1.0, 0.2, 20.0), (1.0, -0.15, -40.0),
                                                 (2.0, -0.3, 35.0), (0.6, 0.1, 50.0)])
def test_apriltag_id_and_pose_in_the_base_frame(how, ahead, left, turned):
    rng = np.random.default_rng(int(ahead * 100 + turned))
    img = degrade(scene(rng, tags=[tag_at(7, ahead, left, turned)]), rng, HOW[how])
    tags = FiducialDetector().detect(img, CAMERA.camera_matrix, None, CAMERA.camera_from_body)
    assert [t.id for t in tags] == [7]
    t = tags[0]
    x, y, z = t.position_m
    # range: within 4 % to 1 m; a far tag (20 px wide at 2 m) within 6 %
    rel = 0.04 if ahead <= 1.0 else 0.06
    assert abs(x - ahead) < rel * ahead and abs(y - left) < 0.03 and abs(z - 0.2) < 0.02
    assert abs(t.distance_m - math.hypot(ahead, left)) < rel * ahead
    # the face points back at the robot, turned by `turned`; a small far tag's turn is the least certain
    assert _angle_error_deg(t.facing_rad, math.radians(180 + turned)) < (4.0 if ahead <= 1.0 else 15.0)


def test_aruco_and_apriltag_families_side_by_side():
    rng = np.random.default_rng(3)
    img = degrade(scene(rng, tags=[tag_at(2, 1.0, 0.25, family="aruco_4x4_50"), tag_at(11, 1.0, -0.25)]), rng)
    found = FiducialDetector(("apriltag_36h11", "aruco_4x4_50")).detect(img)
    assert [(t.family, t.id) for t in found] == [("apriltag_36h11", 11), ("aruco_4x4_50", 2)]
    only_april = FiducialDetector().detect(img)
    assert [t.id for t in only_april] == [11]


def test_a_plain_wall_shows_no_tag():
    rng = np.random.default_rng(4)
    assert FiducialDetector().detect(degrade(scene(rng), rng)) == []


def test_marker_image_is_the_dictionarys_marker():
    img = marker_image("apriltag_36h11", 5, 200)
    corners, ids, _ = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
                                              ).detectMarkers(img)
    assert ids is not None and ids.ravel().tolist() == [5]


@pytest.mark.parametrize("how", ["clean", "photo"])
@pytest.mark.parametrize("turned", [0.0, 20.0, 40.0])
def test_qr_board_text(how, turned):
    rng = np.random.default_rng(int(turned))
    board = {"text": "door-3", "size_m": 0.2, "x": 0.5, "y": 0.05, "z_m": 0.2, "facing_deg": 180 + turned}
    img = degrade(scene(rng, qr_boards=[board]), rng, HOW[how])
    found = QrReader().read(img)
    assert [d.text for d in found] == ["door-3"]
    assert abs(found[0].bearing_rad(CAMERA.camera_matrix) - math.atan2(0.05, 0.5)) < math.radians(3)


def test_no_qr_text_on_a_tag():
    rng = np.random.default_rng(5)
    assert QrReader().read(degrade(scene(rng, tags=[tag_at(1, 0.6, 0.0)]), rng)) == []


def _frames_with_person(rng: np.random.Generator, n: int, person_from: int):
    """n photo-like frames of a wall; from frame `person_from` on, a dark figure walks across it."""
    base = scene(rng)
    for i in range(n):
        img = base.copy()
        if i >= person_from:
            x = 40 + 12 * (i - person_from)
            cv2.rectangle(img, (x, 70), (x + 22, 170), (60, 60, 150), -1)
        yield degrade(img, rng)


def test_motion_fires_when_a_person_walks_in_and_not_on_noise():
    rng = np.random.default_rng(6)
    detector = MotionDetector()
    results = [detector.process(img) for img in _frames_with_person(rng, 30, 20)]
    assert not any(r.moving for r in results[:20])  # warm-up and then still noise, JPEG and flicker of noise
    assert all(r.moving for r in results[21:])
    box = results[25].box_px
    assert box is not None and 90 <= box[0] <= 120


def test_motion_is_off_while_the_robot_moves_and_relearns_after():
    rng = np.random.default_rng(7)
    detector = MotionDetector()
    frames = list(_frames_with_person(rng, 30, 0))
    for img in frames[:10]:
        assert not detector.process(img, still=False).moving
    after = [detector.process(img).moving for img in frames[10:]]
    assert not any(after[:detector.warmup_frames])  # warming up again
    assert any(after[detector.warmup_frames:])


@pytest.mark.parametrize("how", ["clean", "photo"])
def test_largest_red_blob_bearing_and_area(how):
    rng = np.random.default_rng(8)
    img = scene(rng, patches=[((30, 30, 200), (220, 80, 40, 60)), ((40, 40, 190), (20, 20, 10, 10)),
                              ((200, 60, 40), (100, 100, 30, 30))])
    img = degrade(img, rng, HOW[how])
    finder = ColourFinder()
    blob = finder.find(img, ColourRange.parse("red"))
    assert blob is not None
    assert abs(blob.area_frac - 40 * 60 / (320 * 240)) < 0.01
    u = blob.centre_px[0]
    assert abs(u - 239.5) < 3
    k = CAMERA.camera_matrix
    assert abs(blob.bearing_rad(k) - (-math.atan2(239.5 - k[0, 2], k[0, 0]))) < math.radians(1)
    blue = finder.find(img, ColourRange.parse("blue"))
    assert blue is not None and abs(blue.centre_px[0] - 114.5) < 3
    assert finder.find(img, ColourRange.parse("green")) is None
    assert finder.find(img, ColourRange.parse("yellow")) is None


def test_colour_by_hsv_box_and_its_errors():
    assert ColourRange.parse({"hsv": [[100, 100, 50], [130, 255, 255]]}).boxes == (((100, 100, 50), (130, 255, 255)),)
    assert len(ColourRange.parse({"hsv": [[170, 100, 50], [10, 255, 255]]}).boxes) == 2  # through red
    with pytest.raises(ValueError, match="unknown colour 'purple'"):
        ColourRange.parse("purple")
    with pytest.raises(ValueError, match="hue 0-179"):
        ColourRange.parse({"hsv": [[200, 0, 0], [210, 255, 255]]})


def test_qr_reads_on_a_worker_thread_do_not_hold_the_caller():
    import time as _time
    from beastbt.blackboard.types import CameraFrame
    from beastbt.vision.watch import VisionRates, VisionWatch
    rng = np.random.default_rng(0)
    board = {"text": "door-3", "size_m": 0.2, "x": 0.5, "y": 0.0, "z_m": 0.2, "facing_deg": 180}
    frame = CameraFrame(0.0, scene(rng, qr_boards=[board]), 1)
    now = [0.0]
    watch = VisionWatch(lambda: CameraFrame(now[0], frame.image, int(now[0] * 10) + 1), CAMERA,
                        rates=VisionRates(qr_hz=100.0), background_qr=True)
    try:
        assert watch.qr_codes(0.0) is None  # the first read is under way: no answer yet (unknown)
        texts = None
        for i in range(1, 200):
            now[0] = i * 0.1
            got = watch.qr_codes(now[0])
            if got:
                texts = [q.text for q in got]
                break
            _time.sleep(0.01)  # the test waits for the worker; the watch itself never does
        assert texts == ["door-3"]
    finally:
        watch.close()


def test_the_watch_builds_the_camera_again_only_when_the_gimbal_the_size_or_the_mounting_changed():
    from dataclasses import replace

    from beastbt.blackboard.types import CameraFrame
    from beastbt.vision.calibration import CameraIntrinsics
    from beastbt.vision.watch import VisionWatch
    gimbal = [(0.3, -0.1)]
    image = [np.zeros((240, 320, 3), np.uint8)]
    watch = VisionWatch(lambda: CameraFrame(0.0, image[0], 1), CAMERA, lambda: gimbal[0])

    def same(a, b):  # the matrices the detectors take
        return (np.array_equal(a.camera_matrix, b.camera_matrix) and np.array_equal(a.dist_coeffs, b.dist_coeffs)
                and np.array_equal(a.camera_from_body, b.camera_from_body) and a == b)

    first = watch.camera_now(watch.frame(0.0))
    assert same(first, CAMERA.with_pan_tilt(0.3, -0.1))  # as a fresh build
    assert watch.camera_now(watch.frame(0.0)) is first  # the same inputs: not built again
    gimbal[0] = (0.5, -0.1)  # panned
    panned = watch.camera_now(watch.frame(0.0))
    assert panned is not first and same(panned, CAMERA.with_pan_tilt(0.5, -0.1))
    image[0] = np.zeros((480, 640, 3), np.uint8)  # a bigger frame
    assert same(watch.camera_now(watch.frame(0.0)), CAMERA.with_pan_tilt(0.5, -0.1).scaled_to(640, 480))
    lens = CameraIntrinsics(320, 240, 300.0, 300.0, 160.0, 120.0, (0.1, 0.0, 0.0, 0.0, 0.0))
    watch.geometry = replace(CAMERA, intrinsics=lens)  # calibrated: a new mounting object
    calibrated = watch.camera_now(watch.frame(0.0))
    assert same(calibrated, watch.geometry.with_pan_tilt(0.5, -0.1).scaled_to(640, 480))
    assert calibrated.dist_coeffs[0] == 0.1 and calibrated.camera_matrix[0, 0] == 600.0
