"""What people see of a map: the saved map, the places on it, the planned path and the path driven.

* :func:`draw_map`: the map on a matplotlib axes in the map frame (metres), free white, occupied black, unknown
  grey, as RViz and ``map_server`` show it; with places (a dot, the name, the arrival tolerance) and paths. Used by
  ``beastbt map show`` and by the report.
* the Foxglove messages of ``/map`` (:func:`map_grid`, a ``foxglove.Grid`` of ``int8`` occupancy, -1 unknown, 0
  free, 100 occupied, as ``nav_msgs/OccupancyGrid``; published once, latched, and again when the planner marks new
  lethal cells) and ``/path`` (:func:`path_update`, a ``foxglove.SceneUpdate`` line);
* :class:`MapSampler`, on the tick side: the map (once) and the planned path (``global_plan``) when they change.
"""

from __future__ import annotations

import base64
import math
from typing import Any, Iterable, Optional, Sequence

import numpy as np

from beastbt.blackboard import catalogue
from beastbt.recording.foxglove import color, fox_time, planar_pose, vector3

POSE_PERIOD_S = 0.2
"""The pose on the map goes to the recording at most this often (5 Hz), s: the report draws the driven path."""
GRID_INT8 = 2
"""``foxglove.NumericType`` INT8."""
PATH_ID = "global_plan"
_PATH = color(0.15, 0.45, 1.0, 1.0)
_FOREVER = {"sec": 0, "nsec": 0}

FREE_RGB = (1.0, 1.0, 1.0)
OCCUPIED_RGB = (0.0, 0.0, 0.0)
UNKNOWN_RGB = (0.80, 0.80, 0.80)


def map_rgb(grid: Any) -> np.ndarray:
    """The map as an RGB image (rows, cols, 3) of floats, row 0 at the bottom (the map's own order)."""
    image = np.empty(grid.data.shape + (3,))
    image[:] = UNKNOWN_RGB
    image[grid.free()] = FREE_RGB
    image[grid.occupied()] = OCCUPIED_RGB
    return image


def draw_map(ax: Any, grid: Any, places: Iterable[Any] = (), planned: Optional[Sequence] = None,
             driven: Optional[Sequence] = None, start: Optional[tuple[float, float, float]] = None) -> None:
    """Draw ``grid`` on ``ax`` in the map frame (m, x right, y up), with ``places`` (objects with ``name``, ``x``,
    ``y`` and ``tolerance_m``), a ``planned`` path and a ``driven`` one ((n, 2) metres each) and the ``start`` pose
    (x m, y m, yaw rad)."""
    from matplotlib.patches import Circle
    if grid.origin_yaw:
        raise ValueError("drawing a map whose origin is rotated is not supported")
    extent = (grid.origin_x, grid.origin_x + grid.width_m, grid.origin_y, grid.origin_y + grid.height_m)
    ax.imshow(map_rgb(grid), origin="lower", extent=extent, interpolation="nearest", zorder=0)
    if planned is not None and len(planned) > 1:
        p = np.asarray(planned, dtype=float)
        ax.plot(p[:, 0], p[:, 1], "-", color="#2f6fff", lw=1.6, label="planned path", zorder=3)
    if driven is not None and len(driven) > 1:
        d = np.asarray(driven, dtype=float)
        ax.plot(d[:, 0], d[:, 1], "-", color="#d9480f", lw=1.2, label="driven path", zorder=4)
    if start is not None:
        x, y, yaw = start
        ax.annotate("", xy=(x + 0.5 * math.cos(yaw), y + 0.5 * math.sin(yaw)), xytext=(x, y),
                    arrowprops={"arrowstyle": "->", "color": "#2b8a3e", "lw": 1.8}, zorder=5)
        ax.plot([x], [y], "o", color="#2b8a3e", ms=5, zorder=5, label="start (map origin)" if (x, y) == (0, 0)
                else "start")
    for place in places:
        ax.plot([place.x], [place.y], "o", color="#c2255c", ms=5, zorder=6)
        if getattr(place, "tolerance_m", None):
            ax.add_patch(Circle((place.x, place.y), place.tolerance_m, fill=False, ec="#c2255c", lw=0.8, zorder=6))
        ax.annotate(place.name, (place.x, place.y), xytext=(4, 4), textcoords="offset points", fontsize=8,
                    color="#c2255c", zorder=7)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, map frame)")
    ax.set_ylabel("y (m)")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=7, framealpha=0.8)


def save_map_png(grid: Any, out: str, title: str = "", **what: Any) -> None:
    """Draw the map (see :func:`draw_map` for ``what``) into a PNG at ``out``; about 100 pixels per 1.5 m."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    aspect = grid.height_m / max(grid.width_m, 1e-9)
    width = min(14.0, max(5.0, grid.width_m * 0.6))
    fig, ax = plt.subplots(figsize=(width, max(3.0, width * aspect) + 0.6))
    try:
        draw_map(ax, grid, **what)
        if title:
            ax.set_title(title, fontsize=10)
        fig.tight_layout()
        fig.savefig(out, dpi=110)
    finally:
        plt.close(fig)


# -- Foxglove ---------------------------------------------------------------------------------------------------

def map_grid(t_ns: int, frame_id: str, grid: Any, lethal: Optional[np.ndarray] = None) -> dict:
    """The map as a ``foxglove.Grid`` in ``frame_id`` (map): one ``int8`` field ``occupancy`` (-1 unknown, 0 free,
    100 occupied, as ``nav_msgs/OccupancyGrid``), row 0 the bottom row. ``lethal``: cells the planner marked since
    (something in the way the map did not show), drawn occupied."""
    data = np.ascontiguousarray(grid.data, dtype=np.int8)
    if lethal is not None:
        data = data.copy()
        data[lethal] = 100
    return {"timestamp": fox_time(t_ns), "frame_id": frame_id,
            "pose": planar_pose(float(grid.origin_x), float(grid.origin_y), float(grid.origin_yaw)),
            "column_count": int(grid.cols), "cell_size": {"x": float(grid.resolution_m), "y": float(grid.resolution_m)},
            "row_stride": int(grid.cols), "cell_stride": 1,
            "fields": [{"name": "occupancy", "offset": 0, "type": GRID_INT8}],
            "data": base64.b64encode(data.tobytes()).decode("ascii")}


def path_update(t_ns: int, frame_id: str, plan: Any) -> dict:
    """The planned path (a :class:`~beastbt.blackboard.types.GlobalPlan`) as a ``foxglove.SceneUpdate`` line in
    ``frame_id`` (map), blue; None deletes it."""
    if plan is None or len(plan.points_xy) < 2:
        return {"deletions": [{"timestamp": fox_time(t_ns), "type": 0, "id": PATH_ID}], "entities": []}
    pts = np.asarray(plan.points_xy, dtype=float)
    line = {"type": 0, "pose": planar_pose(0.0, 0.0, 0.0), "thickness": 0.05, "scale_invariant": False,
            "points": [vector3(float(x), float(y), 0.02) for x, y in pts.tolist()], "color": _PATH, "colors": [],
            "indices": []}
    entity = {"timestamp": fox_time(t_ns), "frame_id": frame_id, "id": PATH_ID, "lifetime": dict(_FOREVER),
              "frame_locked": False, "metadata": [{"key": "goal", "value": str(plan.goal)},
                                                  {"key": "length_m", "value": f"{plan.length_m:.2f}"}],
              "arrows": [], "cubes": [], "spheres": [], "cylinders": [], "lines": [line], "triangles": [],
              "texts": [], "models": []}
    return {"deletions": [], "entities": [entity]}


def map_pose_message(t_ns: int, frame_id: str, pose: tuple) -> dict:
    """The pose on the map ``(x m, y m, yaw rad, localized)`` as a ``foxglove.PoseInFrame`` in ``frame_id`` (map)."""
    return {"timestamp": fox_time(t_ns), "frame_id": frame_id, "pose": planar_pose(pose[0], pose[1], pose[2])}


def grid_of_message(msg: dict) -> Any:
    """The :class:`~beastbt.mapping.occupancy_map.OccupancyMap` of a ``/map`` message (its inverse of
    :func:`map_grid`, for the report)."""
    from beastbt.mapping.occupancy_map import OccupancyMap
    cols = int(msg["column_count"])
    data = np.frombuffer(base64.b64decode(msg["data"]), dtype=np.int8).reshape(-1, cols)
    p, q = msg["pose"]["position"], msg["pose"]["orientation"]
    yaw = 2.0 * math.atan2(float(q["z"]), float(q["w"]))
    return OccupancyMap(data.copy(), float(msg["cell_size"]["x"]), float(p["x"]), float(p["y"]), yaw)


class MapSampler:
    """On the tick side: the mission's map once (and again when the planner marked cells lethal) and the planned
    path when it changes; :meth:`sample` returns ``{"map": (grid, lethal or None)}`` and/or ``{"path": plan or
    None}`` and ``{"map_pose": (x, y, yaw, localized)}`` (at most every :data:`POSE_PERIOD_S`), or an empty dict."""

    def __init__(self, run: Any) -> None:
        import py_trees
        self.run = run
        self.grid = getattr(getattr(run, "mission", None), "map_grid", None)
        self._board = py_trees.blackboard.Client(name="map_views")
        catalogue.register(self._board, "global_plan")
        catalogue.register(self._board, "map_pose")
        self._pose_s = -math.inf
        self._known_free = ~(self.grid.occupied() | self.grid.unknown()) if self.grid is not None else None
        self._sent_map = False
        self._lethal_cells = 0
        self._plan: Any = None

    def sample(self, now_s: float) -> dict:
        """What changed since the last call."""
        out: dict = {}
        if self.grid is None:
            return out
        planner = self.run.ctx.services.plugins.get("map_planner")
        costmap = getattr(planner, "_costmap", None) if planner is not None else None
        # cells marked since the map was made: lethal but neither occupied nor unknown on the map itself
        lethal = costmap.lethal & self._known_free if costmap is not None else None
        marked = int(np.count_nonzero(lethal)) if lethal is not None else 0
        if not self._sent_map or (lethal is not None and marked != self._lethal_cells):
            self._sent_map = True
            self._lethal_cells = marked
            out["map"] = (self.grid, None if lethal is None else lethal.copy())
        plan = catalogue.get(self._board, "global_plan")
        if plan is not self._plan:
            self._plan = plan
            out["path"] = plan
        pose = catalogue.get(self._board, "map_pose")
        if pose is not None and now_s - self._pose_s >= POSE_PERIOD_S - 1e-9:
            self._pose_s = now_s
            out["map_pose"] = (float(pose.x), float(pose.y), float(pose.yaw), bool(pose.localized))
        return out


__all__ = ["draw_map", "save_map_png", "map_rgb", "map_grid", "path_update", "map_pose_message", "grid_of_message",
           "MapSampler", "PATH_ID", "POSE_PERIOD_S"]
