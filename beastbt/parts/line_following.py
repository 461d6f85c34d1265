"""Line following in a run: the ``follow_line`` step, the camera switched on when used, truth scores.

* ``follow_line`` (:class:`~beastbt.behaviours.follow_line.FollowLine`), in
  place of the "not available" leaf, on robots with the ``camera``
  capability; tuned by the profile's ``line_follower:`` section.
* When the run is assembled: the camera pipeline (opened by
  :mod:`beastbt.parts.camera`) and the follower's tuning become the
  ``camera`` and ``line_follower`` services; in the simulator the camera is
  switched on when the mission uses it (``follow_line``, ``snapshot``, the
  ``intersection`` and ``line_seen`` conditions), its floor built then (so a
  bad floor stops the run before anything moves), and
  :class:`~beastbt.run.line_metrics.LineTruthMetrics` scores every
  ``follow_line`` step against the floor's truth (summary ``truth.line_*``
  and ``truth.*intersections*``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Optional

import py_trees

from beastbt.behaviours.operator import NotAvailable
from beastbt.mission.compile import Compiler, StepBuilder
from beastbt.mission import steps as st
from beastbt.core.units import format_quantity
from beastbt.robot.part import Part
from beastbt.robot.profile import section_config
from beastbt.run.session import Prepared

if TYPE_CHECKING:
    # OpenCV comes with the camera pipeline: imported only for a run that has a camera. The follow_line behaviour
    # is imported where a leaf is made or a run installed: `beastbt tree` loads this part (for its step) without it.
    from beastbt.behaviours.follow_line import FollowLine
    from beastbt.vision.camera_pipeline import CameraPipeline

CAMERA_STEPS = frozenset({"follow_line", "snapshot"})
"""Steps that need camera frames."""
CAMERA_CONDITIONS = frozenset({"intersection", "line_seen"})
"""Conditions that need line observations."""
NOT_CONDITIONS = frozenset({"say", "description", "mission", "places", "world"})
"""Mission keys whose text is never a condition."""


# -- the step ------------------------------------------------------------------------------

def _follow_line(c: Compiler, s: st.FollowLine) -> py_trees.behaviour.Behaviour:
    if s.amount is not None:
        label = f"for {format_quantity(s.amount, 'distance' if s.until == 'distance' else 'duration')}"
    else:
        label = f"until {s.until.replace('_', ' ')}"
    name = f"follow line {label}" + (f" at {format_quantity(s.speed_mps, 'speed')}" if s.speed_mps is not None else "")
    if "camera" not in c.ctx.capabilities:
        return NotAvailable(name, c.ctx, "follow_line needs a camera, and this robot has none (add a camera: section)")
    from beastbt.behaviours.follow_line import FollowLine
    return FollowLine(name, c.ctx, s.until, s.amount, s.speed_mps, s.lost_after_s)


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
    from beastbt.behaviours.follow_line import FollowLine
    return [n for n in root.iterate() if isinstance(n, FollowLine)]


def install_vision(prepared: Prepared) -> None:
    """The camera and follower services; the camera on if the mission uses it; in the simulator, score it."""
    run = prepared.run
    profile = prepared.profile
    from beastbt.behaviours.follow_line import FollowLineConfig
    follower: FollowLineConfig = section_config(profile, "line_follower", FollowLineConfig)
    run.ctx.services.line_follower = follower
    pipeline: Optional["CameraPipeline"] = run.io.camera
    if pipeline is None:
        return
    run.ctx.services.camera = pipeline
    uses = camera_uses(prepared.mission.doc.data if prepared.mission.doc is not None else {})
    for why in uses:
        pipeline.enable(why)  # on the robot this starts the camera's thread; a missing camera is reported now
    if run.io.sim is None:
        return
    floor = run.io.floor_map
    nodes = follow_nodes(run.root)
    if floor is not None and nodes and (prepared.world is not None and prepared.world.section("floor") is not None):
        from beastbt.run.line_metrics import LineTruthMetrics
        floor()  # build it now: a bad floor is an InvalidInput before anything moves
        metrics = LineTruthMetrics(floor, nodes)
        run.recorders.append(metrics.on_tick)
        run.ctx.services.line_metrics = metrics


def _summary(run: Any, summary: dict) -> None:
    metrics = run.ctx.services.line_metrics  # set only in the simulator, with a floor and a follow_line step
    if metrics is not None and "truth" in summary:
        summary["truth"].update(metrics.summary())
    pipeline = run.ctx.services.camera
    if pipeline is not None and pipeline.enabled:
        summary["camera"] = {"frames": pipeline.frames, "enabled_for": list(pipeline.reasons)}



class LineFollowingPart(Part):
    """Line following: the follow_line step, the camera switched on when used, truth scores in the simulator."""

    name = "line_following"
    section = "line_follower"
    schema = "parts/line_follower.schema.json"

    def steps(self) -> Mapping[str, StepBuilder]:
        """follow_line."""
        return {"follow_line": _follow_line}

    def install(self, prepared: Prepared) -> None:
        """The camera and follower services; in the simulator, the camera on when the mission uses it."""
        install_vision(prepared)

    def summarise(self, run: Any, summary: dict) -> None:
        """``camera`` (frames, why it was on) and, in the simulator, the line truth metrics."""
        _summary(run, summary)


__all__ = ["LineFollowingPart", "install_vision", "camera_uses", "follow_nodes"]
