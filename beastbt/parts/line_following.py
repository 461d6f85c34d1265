"""The camera in every run: the ``follow_line`` step, the real camera, switching the simulated one on, truth scores.

What this module adds (it registers itself through the compiler's, the
hardware's, the session's and the summary's hooks):

* ``follow_line`` (:class:`~beastbt.behaviours.follow_line.FollowLine`), in
  place of the "not available" leaf, on robots with the ``camera``
  capability; tuned by the profile's ``line_follower:`` section.
* The real camera (:data:`~beastbt.robot.hardware.HARDWARE_DEVICES`): a
  profile's ``camera:`` is opened with OpenCV's V4L2 backend
  (:func:`~beastbt.devices.camera.open_video_capture`), read and run through
  the line detector in a thread of its own. A camera that is missing is
  reported (``camera_lost``) and retried; the run does not stop for it.
* Before a run starts (:data:`~beastbt.run.session.PREPARE_HOOKS`): the
  camera pipeline and the follower's tuning become the ``camera`` and
  ``line_follower`` services; in the simulator the camera is switched on when
  the mission uses it (``follow_line``, ``snapshot``, the ``intersection``
  and ``line_seen`` conditions), its floor built then (so a bad floor stops
  the run before anything moves), and :class:`~beastbt.run.line_metrics.LineTruthMetrics`
  scores every ``follow_line`` step against the floor's truth (summary
  ``truth.line_*`` and ``truth.*intersections*``).
"""

from __future__ import annotations

from typing import Any, Optional

import py_trees

from beastbt.behaviours.follow_line import FollowLine, FollowLineConfig
from beastbt.behaviours.operator import NotAvailable
from beastbt.devices.camera import Camera, CameraConfig, open_video_capture
from beastbt.mission.compile import Compiler, register_step
from beastbt.core.errors import InvalidInput
from beastbt.mission.model import Step
from beastbt.core.units import format_quantity, parse_quantity
from beastbt.vision.camera_pipeline import CameraPipeline
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.robot.hardware import HARDWARE_DEVICES
from beastbt.run.line_metrics import LineTruthMetrics
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO
from beastbt.run.session import PREPARE_HOOKS, Prepared
from beastbt.run.summary import SUMMARY_CONTRIBUTORS
from beastbt.vision.line_detector import LineDetectorConfig

CAMERA_STEPS = frozenset({"follow_line", "snapshot"})
"""Steps that need camera frames."""
CAMERA_CONDITIONS = frozenset({"intersection", "line_seen"})
"""Conditions that need line observations."""
NOT_CONDITIONS = frozenset({"say", "description", "mission", "places", "world"})
"""Mission keys whose text is never a condition."""


# -- the step ------------------------------------------------------------------------------

@register_step("follow_line")
def _follow_line(c: Compiler, s: Step) -> py_trees.behaviour.Behaviour:
    v = s.value
    until = v["until"]
    if isinstance(until, dict):
        kind = next(iter(until))
        amount = parse_quantity(until[kind], "distance" if kind == "distance" else "duration")
        words = f"{format_quantity(amount, 'distance' if kind == 'distance' else 'duration')}"
        label = f"for {words}"
    else:
        kind, amount, label = until, None, f"until {until.replace('_', ' ')}"
    speed = parse_quantity(v["speed"], "speed") if "speed" in v else None
    lost = parse_quantity(v["lost_after"], "duration") if "lost_after" in v else None
    name = f"follow line {label}" + (f" at {format_quantity(speed, 'speed')}" if speed is not None else "")
    if "camera" not in c.ctx.capabilities:
        return NotAvailable(name, c.ctx, "follow_line needs a camera, and this robot has none (add a camera: section)")
    return FollowLine(name, c.ctx, kind, amount, speed, lost)


# -- the real camera -------------------------------------------------------------------------

def attach_camera(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> None:
    """The profile's camera on V4L2, read and run through the line detector in a thread (``io.sensors['camera']``)."""
    if profile.section("camera") is None:
        return
    config: CameraConfig = section_config(profile, "camera", CameraConfig)
    detector_config: LineDetectorConfig = section_config(profile, "line_detector", LineDetectorConfig)
    sink = events.sink("camera")

    def make_camera() -> Camera:
        return Camera(lambda: open_video_capture(config), clock, sink, config)

    pipeline = CameraPipeline(make_camera, config, detector_config, sink)
    try:
        pipeline.check()
    except ValueError as exc:
        raise InvalidInput([profile.doc.problem(("camera",), f"in 'camera': {exc}",
                                                "lower the camera's pitch_deg or raise line_detector.roi_far_m")]) from None
    pipeline.start_thread()
    io.sensors["camera"] = pipeline.poll
    io.capabilities.add("camera")
    io.extras["camera"] = pipeline
    io.closers.append(pipeline.close)


HARDWARE_DEVICES.append(attach_camera)


# -- every run -------------------------------------------------------------------------------

def camera_uses(data: Any) -> list[str]:
    """Why a mission (its YAML data) needs the camera: the camera steps and conditions it mentions."""
    found: list[str] = []

    def walk(node: Any, key: Optional[str]) -> None:
        if isinstance(node, dict):
            for k, v in node.items():
                if k in NOT_CONDITIONS:
                    continue
                if k in CAMERA_STEPS and k not in found:
                    found.append(k)
                walk(v, k)
        elif isinstance(node, list):
            for item in node:
                walk(item, key)
        elif isinstance(node, str) and node in CAMERA_CONDITIONS and node not in found:
            found.append(node)

    walk(data, None)
    return found


def follow_nodes(root: py_trees.behaviour.Behaviour) -> list[FollowLine]:
    """Every follow_line leaf of a compiled tree."""
    return [n for n in root.iterate() if isinstance(n, FollowLine)]


def install_vision(prepared: Prepared) -> None:
    """PREPARE_HOOK: the camera and follower services; in the simulator, switch the camera on if used and score it."""
    run = prepared.run
    profile = prepared.profile
    follower: FollowLineConfig = section_config(profile, "line_follower", FollowLineConfig)
    run.ctx.services["line_follower"] = follower
    pipeline: Optional[CameraPipeline] = run.io.extras.get("camera")
    if pipeline is None:
        return
    run.ctx.services["camera"] = pipeline
    if run.io.sim is None:
        return
    uses = camera_uses(prepared.mission.doc.data if prepared.mission.doc is not None else {})
    for why in uses:
        pipeline.enable(why)
    floor = run.io.extras.get("floor_map")
    nodes = follow_nodes(run.root)
    if floor is not None and nodes and (prepared.world is not None and prepared.world.section("floor") is not None):
        floor()  # build it now: a bad floor is an InvalidInput before anything moves
        metrics = LineTruthMetrics(floor, nodes)
        run.recorders.append(metrics.on_tick)
        run.ctx.services["line_metrics"] = metrics


PREPARE_HOOKS.append(install_vision)


def _summary(run: Any, summary: dict) -> None:
    metrics = run.ctx.services.get("line_metrics")
    if isinstance(metrics, LineTruthMetrics) and "truth" in summary:
        summary["truth"].update(metrics.summary())
    pipeline = run.ctx.services.get("camera")
    if isinstance(pipeline, CameraPipeline) and pipeline.enabled:
        summary["camera"] = {"frames": pipeline.frames, "enabled_for": list(pipeline.reasons)}


SUMMARY_CONTRIBUTORS.append(_summary)


__all__ = ["attach_camera", "install_vision", "camera_uses", "follow_nodes"]
