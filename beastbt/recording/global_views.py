"""What people see of the global costmap and the global plan: ``/global_costmap``, ``/plan`` and the console's layer.

The global costmap with memory (:mod:`beastbt.navigation.obstacle_layer`) is
what ``go_to``, ``route`` and ``return_home`` plan on: on GPS the rolling
40 m window of :class:`~beastbt.navigation.global_navigator.GlobalNavigator`
in ``odom``; on a saved map the map's walls plus the same obstacle layer
(:class:`~beastbt.behaviours.map_navigation.MapPlanner`) in ``map``.

Two halves, one per process, as for the rest of the recording
(:mod:`beastbt.recording.obstacle_views` samples them with the other views):

* the tick side, :class:`GlobalViewSampler`: at most every
  :data:`GLOBAL_COSTMAP_PERIOD_S`, and only when the layer changed, the
  lethal cells as a :class:`CostmapMarks` (their flat indices: a fence is a
  few hundred of the window's 160,000 cells); and the way round a GPS
  ``go_to`` follows (``GlobalNavigator.following``) each time it changes;
* the writer side, :func:`global_costmap_grid`: the ``foxglove.Grid`` of
  uint8 Nav2 costs, computed by the planner's own
  :class:`~beastbt.navigation.global_planner.GlobalCostmap` (lethal 254,
  inscribed 253, the exponential inflation), cropped to the lethal cells'
  bounding box plus the inflation radius (every cell outside it is free, 0).

:func:`console_layer` is the console's faint layer of the same marks: a PNG
(lethal cells only) placed on the console's plan.
"""

from __future__ import annotations

import base64
import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from beastbt.recording.foxglove import fox_time, planar_pose

GLOBAL_COSTMAP_PERIOD_S = 1.0
"""The global costmap goes to the recording at most this often (1 Hz), and only when its lethal cells changed, s."""
GRID_UINT8 = 1
"""``foxglove.NumericType`` UINT8."""
CONSOLE_RGBA = (255, 170, 60, 110)
"""The console draws a marked cell in this colour (RGBA): a faint orange under the local costmap's magenta."""


@dataclass(frozen=True)
class CostmapMarks:
    """The lethal cells of a global costmap at one moment, and what its costs are computed with.

    ``frame``: ``odom`` (GPS) or ``map`` (a saved map); the grid's lower-left corner (m), cell side (m) and size;
    ``lethal``: the flat indices (row * cols + col, row 0 the southernmost) of the lethal cells (int32):
    the obstacle layer's marks, and on a map its walls too; ``planner``: the profile's
    :class:`~beastbt.navigation.global_planner.GlobalPlannerConfig`; ``footprint_radius_m`` (m).
    """

    frame: str
    origin_x_m: float
    origin_y_m: float
    resolution_m: float
    rows: int
    cols: int
    lethal: np.ndarray
    planner: Any
    footprint_radius_m: float


def global_costmap_source(run: Any) -> Optional[tuple[str, Any, Optional[np.ndarray], Any, float]]:
    """The global costmap ``run`` plans on now: ``(frame, obstacle layer, the map's own lethal cells or None, planner
    config, footprint radius m)``; None before there is one (no LiDAR, or no step has used it yet)."""
    from beastbt.behaviours.map_navigation import MAP_PLANNER
    planner = run.ctx.services.plugins.get(MAP_PLANNER)
    if planner is not None and planner._layer is not None:  # made on the map planner's first plan
        return "map", planner._layer, planner.grid.occupied(), planner.config, planner.footprint_radius_m
    local = run.ctx.services.local_navigator
    g = getattr(local, "global_nav", None) if local is not None else None
    if g is not None:
        return "odom", g.layer, None, g.planner_config, g.footprint_radius_m
    return None


def marks_of(source: tuple[str, Any, Optional[np.ndarray], Any, float]) -> CostmapMarks:
    """The :class:`CostmapMarks` of a :func:`global_costmap_source` as its layer is now."""
    frame, layer, walls, planner, radius = source
    lethal = layer.marked if walls is None else (layer.marked | walls)
    rows, cols = layer.shape
    return CostmapMarks(frame, float(layer.origin_x), float(layer.origin_y), float(layer.resolution_m), int(rows),
                        int(cols), np.flatnonzero(lethal).astype(np.int32), planner, float(radius))


def gps_navigator(run: Any) -> Any:
    """The :class:`~beastbt.navigation.global_navigator.GlobalNavigator` of ``run``'s GPS go_to steps (its
    ``following`` is the way round drawn as ``/plan``), or None (no LiDAR: no local navigator). Read only."""
    local = run.ctx.services.local_navigator
    return getattr(local, "global_nav", None) if local is not None else None


class GlobalViewSampler:
    """On the tick side: the global costmap's marks when they changed (at most every
    :data:`GLOBAL_COSTMAP_PERIOD_S`) and the GPS way round when it changed; :meth:`sample` returns
    ``{"global_costmap": CostmapMarks}`` and/or ``{"gps_plan": (points (n, 2) odom m, goal name) or None}``, or an
    empty dict."""

    def __init__(self, run: Any) -> None:
        self.run = run
        self._checked_s = -math.inf
        self._key: Optional[tuple] = None
        """(layer, version, origin) last looked at: a layer that did not change is not read again."""
        self._sent: Optional[CostmapMarks] = None
        self._following: Any = None

    def sample(self, now_s: float) -> dict:
        """What changed since the last call."""
        out: dict = {}
        g = gps_navigator(self.run)
        if g is not None and g.following is not self._following:
            self._following = g.following
            out["gps_plan"] = None if g.following is None else (np.array(g.following.points, dtype=float),
                                                                 g.goal_name)
        if now_s - self._checked_s < GLOBAL_COSTMAP_PERIOD_S - 1e-9:
            return out
        self._checked_s = now_s
        source = global_costmap_source(self.run)
        if source is None:
            return out
        layer = source[1]
        key = (id(layer), layer.version, layer.origin_x, layer.origin_y)
        if key == self._key:
            return out
        self._key = key
        marks = marks_of(source)
        sent = self._sent
        if sent is None and marks.lethal.size == 0:
            return out  # nothing marked yet: nothing to draw
        if (sent is not None and sent.frame == marks.frame and np.array_equal(sent.lethal, marks.lethal)
                and (sent.origin_x_m, sent.origin_y_m) == (marks.origin_x_m, marks.origin_y_m)):
            return out  # marked and cleared back to the same cells
        self._sent = marks
        out["global_costmap"] = marks
        return out


def crop(marks: CostmapMarks, margin_cells: int) -> Optional[tuple[int, int, np.ndarray]]:
    """(first row, first column, the boolean lethal cells) of the box round the lethal cells widened by
    ``margin_cells`` (within the grid); None when none is lethal."""
    if marks.lethal.size == 0:
        return None
    rr, cc = np.divmod(marks.lethal.astype(np.int64), marks.cols)
    r0, r1 = max(0, int(rr.min()) - margin_cells), min(marks.rows, int(rr.max()) + margin_cells + 1)
    c0, c1 = max(0, int(cc.min()) - margin_cells), min(marks.cols, int(cc.max()) + margin_cells + 1)
    box = np.zeros((r1 - r0, c1 - c0), dtype=bool)
    box[rr - r0, cc - c0] = True
    return r0, c0, box


def global_costs(marks: CostmapMarks) -> Optional[tuple[float, float, np.ndarray]]:
    """(x m, y m of the lower-left corner, uint8 costs (rows, cols)) of the box round the lethal cells plus the
    inflation radius, by the planner's own :class:`~beastbt.navigation.global_planner.GlobalCostmap`; None when
    none is lethal. Every cell outside the box costs 0."""
    from beastbt.mapping.occupancy_map import FREE, OCCUPIED, OccupancyMap
    from beastbt.navigation.global_planner import GlobalCostmap
    res = marks.resolution_m
    cut = crop(marks, int(math.ceil(marks.planner.inflation_radius_m / res)) + 1)
    if cut is None:
        return None
    r0, c0, box = cut
    x0, y0 = marks.origin_x_m + c0 * res, marks.origin_y_m + r0 * res
    # The lethal cells as a map's occupied ones: the costmap's costs are worked out once, as it is made.
    grid = OccupancyMap(np.where(box, OCCUPIED, FREE).astype(np.int8), res, x0, y0)
    return x0, y0, GlobalCostmap(grid, marks.planner, marks.footprint_radius_m).cost


def global_costmap_grid(t_ns: int, frame_id: str, marks: CostmapMarks) -> dict:
    """The global costmap as a ``foxglove.Grid`` in ``frame_id``: one uint8 field ``cost`` (Nav2's values), row 0
    the southernmost, over the box round its lethal cells (:func:`global_costs`); nothing lethal: an empty grid
    (0 columns, a row stride of 1 byte, as ``/costmap`` when taken off)."""
    costs = global_costs(marks)
    if costs is None:
        return {"timestamp": fox_time(t_ns), "frame_id": frame_id, "pose": planar_pose(0.0, 0.0, 0.0),
                "column_count": 0, "cell_size": {"x": 1.0, "y": 1.0}, "row_stride": 1, "cell_stride": 1,
                "fields": [{"name": "cost", "offset": 0, "type": GRID_UINT8}], "data": ""}
    x0, y0, cost = costs
    rows, cols = cost.shape
    res = marks.resolution_m
    return {"timestamp": fox_time(t_ns), "frame_id": frame_id, "pose": planar_pose(x0, y0, 0.0),
            "column_count": int(cols), "cell_size": {"x": res, "y": res}, "row_stride": int(cols), "cell_stride": 1,
            "fields": [{"name": "cost", "offset": 0, "type": GRID_UINT8}],
            "data": base64.b64encode(np.ascontiguousarray(cost, dtype=np.uint8).tobytes()).decode("ascii")}


def gps_plan(plan: Optional[tuple[np.ndarray, str]]) -> Any:
    """The GPS way round as a :class:`~beastbt.blackboard.types.GlobalPlan` (odom, m) for
    :func:`beastbt.recording.map_views.path_update`; None stays None (the line is deleted)."""
    if plan is None:
        return None
    from beastbt.blackboard.types import GlobalPlan
    points, goal = plan
    length = float(np.hypot(*np.diff(points, axis=0).T).sum()) if len(points) > 1 else 0.0
    return GlobalPlan(0.0, points, goal, length)


# -- the console ----------------------------------------------------------------------------------------------

def console_layer(marks: CostmapMarks) -> Optional[dict]:
    """The console's faint layer of the marks: ``png`` (a data URL, north up: the image's top row is the box's
    northernmost), ``corner`` (the box's lower-left corner in the costmap's frame, m), ``width_m`` and
    ``height_m``; None when nothing is lethal. The caller places ``corner`` on its plan."""
    import cv2
    cut = crop(marks, 0)
    if cut is None:
        return None
    r0, c0, box = cut
    rgba = np.zeros(box.shape + (4,), np.uint8)
    rgba[box] = CONSOLE_RGBA
    ok, png = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgba[::-1]), cv2.COLOR_RGBA2BGRA))
    assert ok
    res = marks.resolution_m
    return {"png": "data:image/png;base64," + base64.b64encode(png.tobytes()).decode("ascii"),
            "corner": (marks.origin_x_m + c0 * res, marks.origin_y_m + r0 * res),
            "width_m": box.shape[1] * res, "height_m": box.shape[0] * res}


class ConsoleGlobalLayer:
    """The console's layer of the global costmap (:func:`console_layer`), worked out again at most every
    :data:`GLOBAL_COSTMAP_PERIOD_S` and only when the layer changed; :meth:`now` gives ``(frame, layer)`` or
    None (nothing marked, or no global costmap)."""

    def __init__(self) -> None:
        self._checked_s = -math.inf
        self._key: Optional[tuple] = None
        self._drawn: Optional[tuple[str, dict]] = None

    def now(self, run: Any, now_s: float) -> Optional[tuple[str, dict]]:
        """``(frame, layer)`` of ``run``'s global costmap at ``now_s`` (s, the run's clock)."""
        if now_s - self._checked_s < GLOBAL_COSTMAP_PERIOD_S - 1e-9 and now_s >= self._checked_s:
            return self._drawn
        self._checked_s = now_s
        source = global_costmap_source(run)
        if source is None:
            self._key = self._drawn = None
            return None
        layer = source[1]
        key = (id(layer), layer.version, layer.origin_x, layer.origin_y)
        if key != self._key:
            self._key = key
            drawn = console_layer(marks_of(source))
            self._drawn = None if drawn is None else (source[0], drawn)
        return self._drawn


__all__ = ["CostmapMarks", "ConsoleGlobalLayer", "GlobalViewSampler", "global_costmap_source", "marks_of", "crop", "global_costs",
           "global_costmap_grid", "gps_plan", "gps_navigator", "console_layer", "GLOBAL_COSTMAP_PERIOD_S"]
