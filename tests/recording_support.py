"""Helpers of the recording tests (tests/test_recording_*.py): record a run, look at PNGs."""

from __future__ import annotations

import atexit
import functools
import io
import shutil
import tempfile
from pathlib import Path
from typing import Any, Optional

import numpy as np

from beastbt.assembly import prepare
from beastbt.run.session import RunOptions, execute

REPO = Path(__file__).resolve().parent.parent
PATROL = REPO / "missions" / "patrol.yaml"
GPS_ROUTE = REPO / "missions" / "gps_route.yaml"
TELEOP = REPO / "missions" / "teleop.yaml"
TELEOP_SCRIPT = REPO / "missions" / "joystick/teleop_demo.yaml"

FAILSAFE_MISSION = """
mission: failsafe_demo
steps:
  - drive: {distance: 2 m, speed: 0.2 m/s}
failsafes:
  battery_low: {below: 12.5 V, for: 1 s, then: stop}
"""
"""The simulator's battery starts at 12.3 V: the failsafe triggers after 1 s and stops the run."""


CAMERA_MISSION = """
mission: look_at_the_line
world: WORLD
steps:
  - wait: 2 s
  - snapshot: {name: tape}
"""
"""On the line track: the camera sees the tape (line observations, frames, a snapshot)."""


def record_run(mission: Path, runs_dir: Path, seed: int = 1, max_time_s: Optional[float] = None,
               mission_text: Optional[str] = None, record_path: Optional[Path] = None, record: bool = True,
               **options: Any) -> tuple[Optional[Path], dict]:
    """Run ``mission`` on the simulator at full speed, recorded; return (run folder, summary)."""
    opts = RunOptions(seed=seed, runs_dir=str(runs_dir), max_time_s=max_time_s, record=record,
                      record_path=str(record_path) if record_path else None, **options)
    p = prepare(str(mission), opts, mission_text=mission_text)
    summary = execute(p, io.StringIO())
    return (p.folder.path if p.folder is not None else None), summary


_SHARED_DIR: Optional[Path] = None


@functools.lru_cache(maxsize=None)
def shared_run(name: str) -> tuple[Path, dict]:
    """An example run recorded once per test process and shared by the tests that only read it.

    ``patrol`` (seed 1, 40 s: drives, looks around, turns), ``gps`` (the GPS
    route, seed 1, 55 s: reaches its first place), ``teleop`` (scripted
    joystick), ``failsafe`` (battery_low stops it after 1 s), ``camera``
    (looks at the tape of the line track and takes a snapshot; recorded with
    ``--record-sensors``, so every sensor is in it).
    """
    global _SHARED_DIR
    if _SHARED_DIR is None:
        _SHARED_DIR = Path(tempfile.mkdtemp(prefix="beastbt-recording-tests-"))
        atexit.register(shutil.rmtree, _SHARED_DIR, True)
    runs = _SHARED_DIR / name
    if name == "patrol":
        return record_run(PATROL, runs, seed=1, max_time_s=40.0)
    if name == "gps":
        return record_run(GPS_ROUTE, runs, seed=1, max_time_s=55.0)
    if name == "teleop":
        return record_run(TELEOP, runs, seed=3, joystick_script=str(TELEOP_SCRIPT))
    if name == "camera":
        runs.mkdir(parents=True)
        mission = runs / "camera.yaml"
        mission.write_text(CAMERA_MISSION.replace("WORLD", str(REPO / "worlds" / "line_track.yaml")), encoding="utf-8")
        return record_run(mission, runs, seed=4, record_sensors=True)  # every sensor: GPS, IMU, EKF awake too
    if name == "failsafe":
        runs.mkdir(parents=True)
        mission = runs / "failsafe.yaml"
        mission.write_text(FAILSAFE_MISSION, encoding="utf-8")
        return record_run(mission, runs, seed=2)
    raise KeyError(name)


def without_timestamps(rec: Any) -> dict:
    """``rec.messages`` without the Foxglove ``timestamp`` fields (at any depth: transforms have their own),
    after checking each equals its message's log time.

    Those hold Unix epoch time, which differs run to run; everything else in a run with a given seed does not.
    """
    def strip(node: Any, epoch_ns: int, topic: str) -> Any:
        if isinstance(node, dict):
            stamp = node.get("timestamp")
            if isinstance(stamp, dict) and set(stamp) == {"sec", "nsec"}:
                assert stamp["sec"] * 1_000_000_000 + stamp["nsec"] == epoch_ns, topic
            return {k: strip(v, epoch_ns, topic) for k, v in node.items() if k != "timestamp"}
        if isinstance(node, list):
            return [strip(v, epoch_ns, topic) for v in node]
        return node

    return {topic: [(t, strip(m, t + rec.log_time_offset_ns, topic)) for t, m in entries]
            for topic, entries in rec.messages.items()}


def png_pixels(path: Path) -> np.ndarray:
    """A PNG as a float array (rows, columns, channels), values 0-1."""
    import matplotlib.image
    return matplotlib.image.imread(str(path))


def assert_real_plot(path: Path, size_in: tuple[float, float], dpi: int) -> None:
    """The file is a PNG of the expected pixel size with content: not blank, not one colour, not all white."""
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    img = png_pixels(path)
    assert img.shape[0] == round(size_in[1] * dpi) and img.shape[1] == round(size_in[0] * dpi), img.shape
    grey = img[..., :3].mean(axis=2)
    assert grey.std() > 0.05, f"{path.name}: almost uniform (std {grey.std():.3f})"
    inked = float((grey < 0.9).mean())
    assert inked > 0.01, f"{path.name}: {inked:.2%} of pixels are not white"
    # Colour, not only black axes: the data lines are drawn in colour.
    colourful = float((img[..., :3].max(axis=2) - img[..., :3].min(axis=2) > 0.2).mean())
    assert colourful > 0.001, f"{path.name}: no coloured pixels ({colourful:.3%})"


def rude_person_world(folder) -> str:
    """worlds/corridor_person.yaml with a person who does not give way (``gives_way: false``): it walks into the
    standing robot, the contact these views must show (a person who gives way never touches it)."""
    text = (REPO / "worlds" / "corridor_person.yaml").read_text(encoding="utf-8")
    path = folder / "corridor_rude_person.yaml"
    path.write_text(text.replace("    loop: true", "    gives_way: false\n    loop: true", 1), encoding="utf-8")
    return str(path)
