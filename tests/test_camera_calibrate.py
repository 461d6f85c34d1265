"""``beastbt camera calibrate``: a known camera's intrinsics back from photo-like checkerboard pictures
(tests/checkerboard_photos.py), written into a profile that then uses them; and the photos it refuses."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from beastbt.cli import main
from beastbt.devices.camera import CameraConfig
from beastbt.robot.profile import load_profile, section_config
from beastbt.vision.camera_model import CameraGeometry
from checkerboard_photos import TRUE_CAMERA, write_photos

ROOT = Path(__file__).resolve().parents[1]
BOARD_ARGS = ["--board", "9x6", "--square", "25mm"]


@pytest.fixture(scope="module")
def photos(tmp_path_factory) -> list[str]:
    return write_photos(tmp_path_factory.mktemp("board"), count=8, seed=7)


def calibrate(*args: str) -> int:
    return main(["camera", "calibrate", *args])


def printed(out: str, name: str) -> float:
    """The number after ``name:`` in the command's output."""
    return float(out.split(f"{name}: ")[1].split()[0])


def test_recovers_a_known_camera_from_photo_like_pictures(photos, capsys):
    assert calibrate(*photos, *BOARD_ARGS) == 0
    out = capsys.readouterr().out
    t = TRUE_CAMERA
    assert abs(printed(out, "fx") / t.fx_px - 1.0) < 0.02, out
    assert abs(printed(out, "fy") / t.fy_px - 1.0) < 0.02, out
    assert abs(printed(out, "cx") - t.cx_px) < 3.0, out
    assert abs(printed(out, "cy") - t.cy_px) < 3.0, out
    assert printed(out, "RMS reprojection error") < 0.5, out
    assert "photos: 8 used" in out
    # the true lens's barrel distortion is found (k1 < 0)
    k1 = float(out.split("k3): ")[1].split()[0])
    assert k1 < -0.05, out


def test_writes_the_profile_in_place_and_the_run_reads_it(photos, tmp_path, capsys):
    profile = tmp_path / "beast.yaml"
    shutil.copy(ROOT / "robots" / "ugv_beast.yaml", profile)
    before = profile.read_text(encoding="utf-8")
    out_file = tmp_path / "intrinsics.yaml"
    assert calibrate(*photos, *BOARD_ARGS, "--profile", str(profile), "-o", str(out_file)) == 0
    after = profile.read_text(encoding="utf-8")
    # only lines added, inside camera:, every other byte (comments included) as it was
    added = [line for line in after.splitlines() if line not in before.splitlines()]
    assert after.replace("\n".join(added) + "\n", "") == before
    assert added[0] == "  intrinsics:" and any(line.startswith("    distortion: [") for line in added)
    assert main(["validate", str(profile)]) == 0
    config = section_config(load_profile(profile), "camera", CameraConfig)
    geometry = CameraGeometry.from_config(config)  # the profile's 320x240 from the 640x480 photos
    k = geometry.camera_matrix
    assert abs(k[0, 0] / (TRUE_CAMERA.fx_px / 2) - 1.0) < 0.02 and abs(k[1, 1] / (TRUE_CAMERA.fy_px / 2) - 1.0) < 0.02
    assert abs(k[0, 2] - ((TRUE_CAMERA.cx_px + 0.5) / 2 - 0.5)) < 1.5
    assert geometry.dist_coeffs[0] < -0.05
    # the -o file is a profile fragment that validates as one
    pasted = pasted_profile(tmp_path, out_file.read_text(encoding="utf-8"))
    assert main(["validate", str(pasted)]) == 0
    assert "wrote camera.intrinsics into" in capsys.readouterr().out


def pasted_profile(folder: Path, fragment: str) -> Path:
    """The simulator's profile with the ``camera:`` section replaced by ``fragment`` (plus the device)."""
    text = (ROOT / "robots" / "diy_pwm.yaml").read_text(encoding="utf-8")
    assert "\ncamera:" not in text
    path = folder / "pasted.yaml"
    path.write_text(text + "\n" + fragment.replace("camera:\n", "camera:\n  device: /dev/video0\n"), encoding="utf-8")
    return path


def test_refuses_an_unreadable_file_naming_it_and_writes_nothing(photos, tmp_path, capsys):
    junk = tmp_path / "notes.jpg"
    junk.write_text("not a photo", encoding="utf-8")
    profile = tmp_path / "beast.yaml"
    shutil.copy(ROOT / "robots" / "ugv_beast.yaml", profile)
    assert calibrate(*photos, str(junk), *BOARD_ARGS, "--profile", str(profile)) == 2
    err = capsys.readouterr().err
    assert f"{junk}: not an image" in err and "Traceback" not in err
    assert profile.read_text(encoding="utf-8") == (ROOT / "robots" / "ugv_beast.yaml").read_text(encoding="utf-8")
    assert calibrate(*photos, str(tmp_path / "missing.jpg"), *BOARD_ARGS) == 2
    assert "missing.jpg: no such file; check the path" in capsys.readouterr().err
    # a shell pattern that matched nothing comes as written; a folder is not a photo
    assert calibrate(str(tmp_path / "*.png"), *BOARD_ARGS) == 2
    assert "*.png: no such file; a shell pattern that matches nothing" in capsys.readouterr().err
    assert calibrate(*photos, str(tmp_path), *BOARD_ARGS) == 2
    assert f"{tmp_path}: a folder, not a photo; give the photos in it, such as {tmp_path / '*.jpg'}" in (
        capsys.readouterr().err)


def test_refuses_a_photo_of_another_size(photos, tmp_path, capsys):
    small = tmp_path / "small.jpg"
    cv2.imwrite(str(small), cv2.resize(cv2.imread(photos[0]), (320, 240)))
    assert calibrate(*photos[:3], str(small), *BOARD_ARGS) == 2
    err = capsys.readouterr().err
    assert f"{small}: 320x240 pixels, but {photos[0]} is 640x480" in err


def test_refuses_too_few_photos_with_the_board(photos, tmp_path, capsys):
    blank = tmp_path / "wall.png"
    cv2.imwrite(str(blank), np.full((480, 640), 128, np.uint8))
    assert calibrate(*photos[:3], str(blank), *BOARD_ARGS) == 2
    err = capsys.readouterr().err
    assert "found in 3 of 4 photos" in err and "at least 5" in err and f"{blank}: no 9x6 board found" in err
    # a board named wrongly finds nothing in any of them
    assert calibrate(*photos[:5], "--board", "10x7", "--square", "25mm") == 2
    assert "found in 0 of 5 photos" in capsys.readouterr().err


@pytest.mark.parametrize("args, message", [
    (["--board", "9", "--square", "25mm"], "--board '9': expected the inner corners as COLSxROWS"),
    (["--board", "6x6", "--square", "25mm"], "is square, so its orientation is ambiguous"),
    (["--board", "9x6", "--square", "25"], "--square '25'"),
])
def test_refuses_a_bad_board(photos, capsys, args, message):
    assert calibrate(*photos[:5], *args) == 2
    assert message in capsys.readouterr().err


def test_the_docs_profile_example_validates_and_is_read(tmp_path):
    doc = (ROOT / "docs" / "vision.md").read_text(encoding="utf-8")
    section = doc.split("## Calibrating the camera")[1].split("\n## ")[0]
    example = next(b for b in section.split("```yaml\n")[1:]).split("```")[0]
    path = tmp_path / "profile.yaml"
    path.write_text((ROOT / "robots" / "diy_pwm.yaml").read_text(encoding="utf-8") + "\n" + example, encoding="utf-8")
    assert main(["validate", str(path)]) == 0
    geometry = CameraGeometry.from_config(section_config(load_profile(path), "camera", CameraConfig))
    assert geometry.camera_matrix[0, 0] == pytest.approx(609.72 / 2) and geometry.dist_coeffs[1] == 0.18034


def test_a_calibrated_lens_distortion_reaches_the_tags_pose():
    # A tag near the picture's edge seen through a barrel lens: with the profile's intrinsics (the lens's
    # distortion) the vision service places it right; as the ideal pinhole it would be placed too far away.
    from dataclasses import replace

    from beastbt.blackboard.types import CameraFrame
    from beastbt.vision.calibration import CameraIntrinsics
    from beastbt.vision.watch import VisionWatch
    from photo_like import CAMERA, scene, tag_at
    k = CAMERA.camera_matrix
    lens = CameraIntrinsics(CAMERA.width_px, CAMERA.height_px, k[0, 0], k[1, 1], k[0, 2], k[1, 2],
                            (-0.35, 0.1, 0.0, 0.0, 0.0))
    rng = np.random.default_rng(3)
    ideal = scene(rng, tags=[tag_at(5, 0.9, 0.32, 0.0, size_m=0.16)])
    # the picture as the lens bends it: each of its pixels shows where the ideal camera would see that ray
    h, w = ideal.shape[:2]
    uv = np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1).reshape(-1, 1, 2).astype(np.float64)
    ideal_uv = cv2.undistortPoints(uv, k, np.array(lens.distortion), P=k).reshape(h, w, 2).astype(np.float32)
    bent = cv2.remap(ideal, ideal_uv[..., 0], ideal_uv[..., 1], cv2.INTER_LINEAR)
    frame = CameraFrame(0.0, bent, 1)

    def placed(geometry: CameraGeometry) -> tuple[float, ...]:
        tags = VisionWatch(lambda: frame, geometry).tags(0.0)
        assert tags is not None and [t.id for t in tags] == [5]
        return tags[0].position_m

    x, y, _ = placed(replace(CAMERA, intrinsics=lens))
    assert abs(x - 0.9) < 0.015 and abs(y - 0.32) < 0.015, (x, y)
    x, _, _ = placed(CAMERA)
    assert x - 0.9 > 0.04, x  # without the calibration: the tag looks smaller, so farther
