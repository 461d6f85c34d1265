"""What a mission asks the camera: ``{sees: ...}``, ``photo``, ``alert``, ``dock``, ``undock`` and ``track``.

* Steps: ``photo`` (:class:`~beastbt.behaviours.photo.TakePhoto`), ``alert``
  (:class:`~beastbt.behaviours.photo.RaiseAlert`), ``dock`` and ``undock``
  (:mod:`beastbt.behaviours.dock`), ``track`` (:mod:`beastbt.behaviours.track`); on a robot without a
  camera ``photo``, ``dock`` and ``track`` fail
  saying so, and an alert goes without its photo.
* When the run is assembled, and only for a mission that uses these words: the detectors
  (:class:`~beastbt.vision.watch.VisionWatch`, ``ctx.services.vision``) and the camera switched on
  for them at :attr:`~beastbt.vision.watch.VisionRates.frame_rate_hz`. Each detector is built and
  run only when a condition or step asks (a mission that waits for a QR code never looks for
  motion), at its own rate; a mission without these words costs nothing.
* In the simulator, each dock's true pose error (``truth.dock_error_m``, ``truth.dock_error_deg``)
  from the robot's true pose and the world's tag.
* The summary: ``vision`` (photos, docks, how often each detector ran) and ``alerts``.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import py_trees

from beastbt.behaviours.operator import NotAvailable
from beastbt.mission import steps as st
from beastbt.mission.compile import Compiler, StepBuilder
from beastbt.core.units import format_quantity
from beastbt.robot.part import Part
from beastbt.run.session import Prepared

VISION_STEPS = frozenset({"photo", "alert", "dock", "undock", "track"})
"""Step keywords of this part."""
CAMERA_WORDS = frozenset({"photo", "alert", "dock", "track"})
"""Steps that need the camera's frames (an alert only with ``photo: true``; ``undock`` never)."""
NOT_STEPS = frozenset({"say", "description", "mission", "places", "world"})
"""Mission keys whose text is never a step or a condition."""


# -- the steps -----------------------------------------------------------------------------

def _photo(c: Compiler, s: st.Photo) -> py_trees.behaviour.Behaviour:
    label = s.name or f"photo-line{s.at.line}"
    if "camera" not in c.ctx.capabilities:
        return NotAvailable(f"photo {label}", c.ctx, "this robot has no camera (no camera: section in its profile)")
    from beastbt.behaviours.photo import TakePhoto
    return TakePhoto(f"photo {label}", c.ctx, label)


def _alert(c: Compiler, s: st.Alert) -> py_trees.behaviour.Behaviour:
    from beastbt.behaviours.photo import RaiseAlert
    short = s.text if len(s.text) <= 30 else s.text[:27] + "..."
    return RaiseAlert(f'alert "{short}"' + (" with a photo" if s.photo else ""), c.ctx, s.text, s.photo)


def _dock(c: Compiler, s: st.Dock) -> py_trees.behaviour.Behaviour:
    name = f"dock at tag {s.tag}, {format_quantity(s.distance_m, 'distance')} from it"
    if "camera" not in c.ctx.capabilities:
        return NotAvailable(name, c.ctx, "dock needs a camera to see the tag, and this robot has none")
    from beastbt.behaviours.dock import Dock
    return Dock(name, c.ctx, s.tag, s.family, s.size_m, s.distance_m, s.speed_mps)


def _track(c: Compiler, s: st.Track) -> py_trees.behaviour.Behaviour:
    from beastbt.vision.colour import ColourRange
    colour = ColourRange.parse(s.colour)
    name = f"track {colour.name} for {format_quantity(s.duration_s, 'duration')}"
    if "camera" not in c.ctx.capabilities:
        return NotAvailable(name, c.ctx, "track needs a camera, and this robot has none")
    from beastbt.behaviours.track import TrackColour
    return TrackColour(name, c.ctx, colour, s.duration_s)


def _undock(c: Compiler, s: st.Undock) -> py_trees.behaviour.Behaviour:
    from beastbt.behaviours.dock import Undock
    return Undock(f"undock {format_quantity(s.distance_m, 'distance')}", c.ctx, s.distance_m)


# -- every run -------------------------------------------------------------------------------

def vision_uses(data: Any) -> list[str]:
    """Why a mission (its YAML data) needs the camera's frames: the camera words and ``sees`` it mentions, in order."""
    found: list[str] = []

    def walk(node: Any) -> None:
        if isinstance(node, dict):
            for k, v in node.items():
                if k in NOT_STEPS:
                    continue
                if k == "alert" and not (isinstance(v, dict) and v.get("photo") is True):
                    continue  # an alert without a photo needs no camera
                if (k in CAMERA_WORDS or k == "sees") and k not in found:
                    found.append(k)
                walk(v)
        elif isinstance(node, list):
            for item in node:
                if isinstance(item, str) and item in CAMERA_WORDS and item not in found:
                    found.append(item)  # a bare `photo` or `undock` step
                walk(item)

    walk(data)
    return found


def _gimbal_reader() -> Any:
    """A function giving the gimbal's (pan, tilt) as last sent to the servos (rad; 0 for a servo never moved)."""
    from beastbt.blackboard import catalogue
    client = py_trees.blackboard.Client(name="vision gimbal")
    catalogue.register(client, "servo_angles")

    def gimbal() -> tuple[float, float]:
        sent = catalogue.get(client, "servo_angles") or {}
        return float(sent.get("pan", 0.0)), float(sent.get("tilt", 0.0))
    return gimbal


def install_vision_watch(prepared: Prepared) -> None:
    """The detectors service and the camera on, for a mission that uses sees/photo/alert/dock; in the simulator,
    each dock's true error."""
    run = prepared.run
    pipeline = run.io.camera
    uses = vision_uses(prepared.mission.doc.data if prepared.mission.doc is not None else {})
    if pipeline is None or not uses:
        return
    from beastbt.vision.watch import VisionWatch

    def latest() -> Any:
        got = pipeline.latest
        return None if got is None else got[0]

    watch = VisionWatch(latest, pipeline.geometry, _gimbal_reader())
    # On the robot the frames come from a thread and the clock is the wall's: a QR read (tens of ms) goes to a
    # worker thread; the simulator reads in lockstep, so that a seed gives the same run.
    watch.background_qr = bool(pipeline.threaded)
    run.ctx.services.vision = watch
    prepared.closers.append(watch.close)
    pipeline.enable("vision", max_rate_hz=watch.rates.frame_rate_hz, lines=False)
    sim = run.io.sim
    if sim is not None and prepared.world is not None:
        tags = prepared.world.data.get("tags") or []
        start = (prepared.world.start_x, prepared.world.start_y, prepared.world.start_yaw)
        watch.on_dock = lambda entry: _dock_truth(entry, sim, tags, start)


def _dock_truth(entry: dict, sim: Any, tags: list, start: tuple[float, float, float]) -> None:
    """The true pose error of a dock (the robot's true pose against the world's tag), into ``entry['truth']``."""
    for t in tags:
        if int(t["id"]) == entry["tag"]:
            facing = math.radians(float(t.get("facing_deg", 0.0)))
            gx = float(t["x"]) + entry["distance_m"] * math.cos(facing)
            gy = float(t["y"]) + entry["distance_m"] * math.sin(facing)
            truth = sim.truth
            err_yaw = math.remainder(truth.yaw - (facing + math.pi), 2 * math.pi)
            entry["truth"] = {"error_m": round(math.hypot(truth.x - gx, truth.y - gy), 4),
                              "error_deg": round(abs(math.degrees(err_yaw)), 2)}
            return


def _summary(run: Any, summary: dict) -> None:
    alerts = [{"time_s": round(e.time_s, 3), "text": e.text} for e in run.events.events if e.kind == "alert"]
    if alerts:
        summary["alerts"] = alerts
    watch = run.ctx.services.vision
    if watch is None:
        return
    summary["vision"] = {"photos": list(watch.log.photos), "docks": list(watch.docks),
                         "detections": dict(sorted(watch.runs.items()))}
    truths = [d["truth"] for d in watch.docks if "truth" in d]
    if truths and "truth" in summary:
        summary["truth"]["dock_error_m"] = truths[-1]["error_m"]
        summary["truth"]["dock_error_deg"] = truths[-1]["error_deg"]


class VisionPart(Part):
    """The camera's mission words: sees, photo, alert, dock, undock (see the module docstring)."""

    name = "vision"

    def steps(self) -> Mapping[str, StepBuilder]:
        """photo, alert, dock, undock, track."""
        return {"photo": _photo, "alert": _alert, "dock": _dock, "undock": _undock,  # type: ignore[dict-item]
                "track": _track}

    def install(self, prepared: Prepared) -> None:
        """The detectors and the camera on, when the mission uses them."""
        install_vision_watch(prepared)

    def summarise(self, run: Any, summary: dict) -> None:
        """``vision`` (photos, docks, detector runs), ``alerts`` and, in the simulator, ``truth.dock_error_*``."""
        _summary(run, summary)


__all__ = ["VisionPart", "vision_uses", "install_vision_watch", "VISION_STEPS"]
