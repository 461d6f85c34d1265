"""What people see of obstacles: the local costmap, the local plan, the collision monitor's zones, the persons;
and, on a map, the localiser's particles and match quality.

Two halves, one per process, as for the rest of the recording:

* the tick side, :class:`ObstacleSampler`: each tick it looks at what the
  views draw (the blackboard's ``costmap`` and ``local_plan``, the run's
  collision monitor, the simulator's persons and truth clearance) and
  returns a ``("views", now_s, {...})`` item holding only what changed, at a
  modest rate (:data:`COSTMAP_PERIOD_S`, :data:`VIEW_PERIOD_S`), so the
  recording grows by little;
* the writer side: the Foxglove messages of those items
  (:func:`costmap_grid`, :func:`plan_update`, :func:`zones_update`,
  :func:`persons_update`, :func:`contact_message`), recorded in the MCAP and
  served live by the same code.

Frames: the costmap and the plan are in ``odom`` (the dead-reckoning frame
of ``/tf``, where :class:`~beastbt.blackboard.types.LocalCostmap` and
:class:`~beastbt.blackboard.types.LocalPlan` live), the zones in
``base_link`` (frame-locked: they ride with the robot), the persons in
``map`` (placed like the world's walls, :meth:`SceneView.world_point`), the
localiser's particles in ``map`` (the saved map's frame, where they live).

A costmap or plan older than :data:`STALE_S` (the step that made it has
ended) counts as absent: it is taken off the views.
"""

from __future__ import annotations

import base64
import math
from typing import Any, Optional

import numpy as np

from beastbt.recording.foxglove import color, fox_time, planar_pose, vector3

COSTMAP_PERIOD_S = 0.5
"""The costmap goes to the recording at most this often (2 Hz), and only when it changed, s."""
VIEW_PERIOD_S = 0.2
"""The plan, the zones' state and the persons go at most this often (5 Hz), and only when they changed, s."""
STALE_S = 1.0
"""A costmap or plan whose ``stamp_s`` is older than this is no longer shown, s."""
LOCALISATION_PERIOD_S = 0.5
"""The map localiser's particles and match quality go at most this often (2 Hz), s."""
PARTICLES_SHOWN = 200
"""At most this many particles are drawn (evenly picked), to keep the recording small."""
PERSON_HEIGHT_M = 1.7
"""How tall a person is drawn, m."""

_STOP = color(0.9, 0.15, 0.15, 0.55)
_STOP_ON = color(1.0, 0.1, 0.1, 1.0)
_SLOW = color(1.0, 0.6, 0.1, 0.5)
_SLOW_ON = color(1.0, 0.65, 0.0, 1.0)
_PLAN = color(0.2, 0.85, 0.3, 1.0)
_PLAN_BLOCKED = color(0.95, 0.25, 0.2, 1.0)
_PERSON = color(0.8, 0.5, 0.95, 0.9)
_FOREVER = {"sec": 0, "nsec": 0}
_IDENTITY = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}

GRID_UINT8 = 1
"""``foxglove.NumericType`` UINT8."""


# -- the tick side -----------------------------------------------------------------------------------


def board_reader() -> Any:
    """A blackboard client that reads ``costmap``, ``local_plan`` and ``global_plan`` (whoever writes them)."""
    import py_trees

    from beastbt.blackboard import catalogue
    client = py_trees.blackboard.Client(name="obstacle_views")
    catalogue.register(client, "costmap")
    catalogue.register(client, "local_plan")
    catalogue.register(client, "global_plan")
    return client


def fresh(value: Any, now_s: float) -> Any:
    """``value`` if it is there and no older than :data:`STALE_S` at ``now_s``, else None."""
    if value is None:
        return None
    stamp = getattr(value, "stamp_s", None)
    if stamp is not None and now_s - float(stamp) > STALE_S:
        return None
    return value


def sim_contact(run: Any) -> Any:
    """The simulator's :class:`~beastbt.sim.contact.ContactWorld` of ``run`` (None on a robot or with nothing to
    touch)."""
    sim = getattr(run.io, "sim", None)
    drive = getattr(sim, "drive", None) if sim is not None else None
    return getattr(drive, "contact", None) if drive is not None else None


class ObstacleSampler:
    """Samples the obstacle views of ``run`` on the tick thread (see the module docstring).

    :meth:`sample` returns the payload of a ``views`` item, or None when
    nothing changed worth sending. Payload keys, each present only when it changed:
    ``costmap`` (a LocalCostmap, or None: taken off), ``plan`` (a LocalPlan or None),
    ``zones`` (``{"zones": monitor.zones(), "action": ...}``), ``global_costmap`` and ``gps_plan``
    (:class:`~beastbt.recording.global_views.GlobalViewSampler`), ``contact``
    (``{"t_s", "clearance_m", "collisions", "in_contact", "persons": [[x, y, r], ...], "moved"}``, world metres;
    ``moved``: the persons are not where the last payload had them).
    """

    def __init__(self, run: Any) -> None:
        self.run = run
        import py_trees  # here: the writer process, which imports this module, needs none
        board = board_reader()
        # Read straight from the blackboard's storage by the client's own key names: through the client (its
        # access checks, a KeyError while nothing is written) a read costs 5 us, and this one 0.5 us.
        self._blackboard = py_trees.blackboard.Blackboard
        self._keys = {name: board.remappings.get(board.absolute_name(name), board.absolute_name(name))
                      for name in ("costmap", "local_plan")}
        self._costmap: Any = None
        self._costmap_s = -math.inf
        self._plan: Any = None
        self._plan_s = -math.inf
        self._board_s = -math.inf
        """Clock time (s) the blackboard's costmap and plan were last looked at."""
        self._zones_action: Optional[str] = None
        self._zones_s = -math.inf
        self._contact = sim_contact(run)
        self._persons = [p.radius_m for p in self._contact.persons] if self._contact is not None else []
        self._contact_s = -math.inf
        self._collisions = 0
        self._last_persons: Optional[list] = None
        from beastbt.recording.map_views import MapSampler
        self._map = MapSampler(run)
        """The saved map and the planned path (a mission with map:), sampled here so they ride the same item."""
        from beastbt.recording.global_views import GlobalViewSampler
        self._global = GlobalViewSampler(run)
        """The global costmap and the GPS way round (/global_costmap, /plan), sampled to ride the same item."""
        self._localiser = run.ctx.services.plugins.get("map_localiser")
        self._localisation_s = -math.inf

    def sample(self, now_s: float) -> Optional[dict]:
        """What changed since the last payload (rate-limited), or None."""
        out: dict = {}
        if now_s - self._board_s >= VIEW_PERIOD_S - 1e-9:
            # The blackboard is looked at only as often as the views may change (a py_trees read costs
            # microseconds, every tick); what the monitor and the contacts say is cheaper, and looked at each tick.
            self._board_s = now_s
            costmap = fresh(self._blackboard.storage.get(self._keys["costmap"]), now_s)
            if costmap is not self._costmap and (costmap is None
                                                 or now_s - self._costmap_s >= COSTMAP_PERIOD_S - 1e-9):
                self._costmap, self._costmap_s = costmap, now_s
                out["costmap"] = costmap
            plan = fresh(self._blackboard.storage.get(self._keys["local_plan"]), now_s)
            if plan is not self._plan and (plan is None or now_s - self._plan_s >= VIEW_PERIOD_S - 1e-9):
                self._plan, self._plan_s = plan, now_s
                out["plan"] = plan
        monitor = self.run.collision_monitor
        if (monitor is not None and monitor.action != self._zones_action
                and now_s - self._zones_s >= VIEW_PERIOD_S - 1e-9):
            self._zones_action, self._zones_s = monitor.action, now_s
            out["zones"] = {"zones": monitor.zones(), "action": monitor.action, "reason": monitor.reason}
        contact = self._contact
        if contact is not None and not contact.empty:
            hit = contact.collisions != self._collisions  # a new contact goes at once: the report marks it
            if hit or now_s - self._contact_s >= VIEW_PERIOD_S - 1e-9:
                self._contact_s, self._collisions = now_s, contact.collisions
                truth = self.run.io.sim.truth
                gap = contact.clearance(truth.x, truth.y)
                persons = [[round(float(x), 3), round(float(y), 3), r]
                           for (x, y), r in zip(contact.person_xy.tolist(), self._persons)]
                moved = persons != self._last_persons
                self._last_persons = persons
                out["contact"] = {"t_s": float(truth.t_s), "clearance_m": gap if math.isfinite(gap) else None,
                                  "collisions": int(contact.collisions), "in_contact": bool(contact.in_contact),
                                  "persons": persons, "moved": moved}
        out.update(self._map.sample(now_s))
        out.update(self._global.sample(now_s))
        loc = self._localiser
        if loc is not None and now_s - self._localisation_s >= LOCALISATION_PERIOD_S - 1e-9:
            self._localisation_s = now_s
            out["localisation"] = localisation_sample(loc)
        return out or None


def localisation_sample(loc: Any) -> dict:
    """What the views draw of a :class:`~beastbt.estimation.map_localiser.MapLocaliser`: up to
    :data:`PARTICLES_SHOWN` particles ``[x, y, yaw]`` in the saved map's frame (m, rad), and the match quality.

    The particles are drawn in ``map``, where they live (as AMCL's particle cloud): on a map, the recording's
    ``/tf`` ``map -> odom`` is taken from ``map_pose`` and the wheels' ``odom`` pose, so ``map`` is the saved map's
    frame and the robot stands in it at ``map_pose``, the cloud's middle. Not ``odom`` through the localiser's own
    ``map -> odom``: that transform is for its odometry, the wheels' travel turned by the gyro, and a tracked base's
    wheels turn 10-15 degrees away from the gyro over a tour: the cloud was drawn turned about ``odom``'s origin,
    away from the robot.
    """
    n = len(loc.px)
    pick = np.linspace(0, n - 1, min(n, PARTICLES_SHOWN)).astype(np.int64) if n else np.zeros(0, dtype=np.int64)
    yaw = (loc.pth[pick] + math.pi) % (2 * math.pi) - math.pi
    particles = np.round(np.column_stack((loc.px[pick], loc.py[pick], yaw)), 3).tolist()
    return {"particles": particles, "match_quality": round(float(loc.match_quality), 3),
            "localized": bool(loc.localized), "updates": int(loc.updates), "particle_count": int(n)}


# -- the writer side: Foxglove messages -----------------------------------------------------------------


def costmap_grid(t_ns: int, frame_id: str, costmap: Any) -> dict:
    """A :class:`~beastbt.blackboard.types.LocalCostmap` as a ``foxglove.Grid`` of uint8 costs in ``frame_id``
    (odom); None as an empty grid (0 x 0: the costmap is taken off the view).

    Row 0 is the southernmost, as in Foxglove (rows along +y, cells along +x from the grid's pose). The empty
    grid has a row stride of 1 byte, so that Foxglove counts its rows as 0 / 1 = 0 and takes it as a valid grid
    of nothing (0 / 0 would be an error on the topic).
    """
    if costmap is None:
        return {"timestamp": fox_time(t_ns), "frame_id": frame_id, "pose": planar_pose(0.0, 0.0, 0.0),
                "column_count": 0, "cell_size": {"x": 1.0, "y": 1.0}, "row_stride": 1, "cell_stride": 1,
                "fields": [{"name": "cost", "offset": 0, "type": GRID_UINT8}], "data": ""}
    cost = np.ascontiguousarray(costmap.cost, dtype=np.uint8)
    rows, cols = cost.shape
    res = float(costmap.resolution_m)
    return {"timestamp": fox_time(t_ns), "frame_id": frame_id,
            "pose": planar_pose(float(costmap.origin_x_m), float(costmap.origin_y_m), 0.0),
            "column_count": int(cols), "cell_size": {"x": res, "y": res}, "row_stride": int(cols), "cell_stride": 1,
            "fields": [{"name": "cost", "offset": 0, "type": GRID_UINT8}],
            "data": base64.b64encode(cost.tobytes()).decode("ascii")}


def _entity(t_ns: int, frame_id: str, entity_id: str, frame_locked: bool = False, **primitives: Any) -> dict:
    entity = {"timestamp": fox_time(t_ns), "frame_id": frame_id, "id": entity_id, "lifetime": dict(_FOREVER),
              "frame_locked": frame_locked, "metadata": [], "arrows": [], "cubes": [], "spheres": [],
              "cylinders": [], "lines": [], "triangles": [], "texts": [], "models": []}
    entity.update(primitives)
    return entity


def _deletion(t_ns: int, entity_id: str) -> dict:
    """A ``foxglove.SceneEntityDeletion`` of one entity by id (type MATCHING_ID)."""
    return {"timestamp": fox_time(t_ns), "type": 0, "id": entity_id}


def _line(points: Any, rgba: dict, thickness_m: float, loop: bool = False, z_m: float = 0.01) -> dict:
    return {"type": 1 if loop else 0, "pose": planar_pose(0.0, 0.0, 0.0), "thickness": thickness_m,
            "scale_invariant": False, "points": [vector3(float(x), float(y), z_m) for x, y in points],
            "color": rgba, "colors": [], "indices": []}


PLAN_ID = "local_plan"
ZONES_ID = "collision_monitor_zones"
PERSONS_ID = "persons"


def plan_update(t_ns: int, frame_id: str, plan: Any) -> dict:
    """The local plan as a ``foxglove.SceneUpdate``: a line in ``frame_id`` (odom), green, red when blocked;
    None deletes it."""
    if plan is None or len(plan.points_xy) < 2:
        return {"deletions": [_deletion(t_ns, PLAN_ID)], "entities": []}
    pts = np.asarray(plan.points_xy, dtype=float)
    metadata = [{"key": "linear_mps", "value": f"{plan.linear_mps:.3f}"},
                {"key": "angular_rps", "value": f"{plan.angular_rps:.3f}"},
                {"key": "blocked", "value": str(bool(plan.blocked)).lower()}]
    line = _line(pts.tolist(), _PLAN_BLOCKED if plan.blocked else _PLAN, 0.04)
    return {"deletions": [], "entities": [_entity(t_ns, frame_id, PLAN_ID, lines=[line], metadata=metadata)]}


def zone_active(action: str) -> tuple[bool, bool]:
    """(stop zone active, slow zone active) for a monitor's action word."""
    return action in ("stop", "silent"), action in ("slow", "approach")


def zones_update(t_ns: int, frame_id: str, state: dict) -> dict:
    """The collision monitor's zones as a ``foxglove.SceneUpdate`` in ``frame_id`` (base_link, frame-locked): the
    stop polygon red, the slow polygon orange, the one acting drawn bold and opaque, the action as a text."""
    zones, action = state["zones"], state["action"]
    stop_on, slow_on = zone_active(action)
    lines = []
    if zones.get("slow"):
        lines.append(_line(zones["slow"], _SLOW_ON if slow_on else _SLOW, 0.03 if slow_on else 0.015, loop=True))
    if zones.get("stop"):
        lines.append(_line(zones["stop"], _STOP_ON if stop_on else _STOP, 0.03 if stop_on else 0.015, loop=True,
                           z_m=0.012))
    texts = []
    if action != "none":
        texts.append({"pose": {"position": vector3(0.0, 0.0, 0.5), "orientation": dict(_IDENTITY)}, "billboard": True,
                      "font_size": 14.0, "scale_invariant": True, "color": _STOP_ON if stop_on else _SLOW_ON,
                      "text": f"collision monitor: {action}"})
    metadata = [{"key": "action", "value": action}, {"key": "reason", "value": str(state.get("reason", ""))}]
    return {"deletions": [], "entities": [_entity(t_ns, frame_id, ZONES_ID, frame_locked=True, lines=lines,
                                                  texts=texts, metadata=metadata)]}


def persons_update(t_ns: int, frame_id: str, persons: list, to_map: Any) -> dict:
    """The persons where they are now as a ``foxglove.SceneUpdate`` of cylinders in ``frame_id`` (map).

    ``persons``: ``[x, y, radius]`` in world metres; ``to_map(x, y)``: world to map metres (None: not placed yet).
    """
    cylinders = []
    for x, y, r in persons:
        xy = to_map(x, y)
        if xy is None:
            continue
        cylinders.append({"pose": {"position": vector3(xy[0], xy[1], 0.5 * PERSON_HEIGHT_M),
                                   "orientation": dict(_IDENTITY)},
                          "size": vector3(2 * r, 2 * r, PERSON_HEIGHT_M), "bottom_scale": 1.0, "top_scale": 1.0,
                          "color": _PERSON})
    return {"deletions": [], "entities": [_entity(t_ns, frame_id, PERSONS_ID, cylinders=cylinders)]}


PARTICLES_ID = "particles"
_PARTICLE = color(0.2, 0.6, 1.0, 0.8)
_PARTICLE_LOST = color(1.0, 0.3, 0.2, 0.8)
PARTICLE_TICK_M = 0.12
"""Length of the stroke that draws a particle from its position along its heading, m."""


def particles_update(t_ns: int, frame_id: str, sample: dict) -> dict:
    """The localiser's particles as a ``foxglove.SceneUpdate`` in ``frame_id`` (map): one short stroke per
    particle along its heading (one line list), blue while localised, red while not."""
    points = []
    for x, y, yaw in sample["particles"]:
        points.append(vector3(x, y, 0.02))
        points.append(vector3(x + PARTICLE_TICK_M * math.cos(yaw), y + PARTICLE_TICK_M * math.sin(yaw), 0.02))
    line = {"type": 2, "pose": planar_pose(0.0, 0.0, 0.0), "thickness": 0.01, "scale_invariant": False,
            "points": points, "color": _PARTICLE if sample["localized"] else _PARTICLE_LOST, "colors": [],
            "indices": []}
    metadata = [{"key": "match_quality", "value": f"{sample['match_quality']:.3f}"},
                {"key": "localized", "value": str(sample["localized"]).lower()},
                {"key": "particles", "value": str(sample["particle_count"])}]
    return {"deletions": [], "entities": [_entity(t_ns, frame_id, PARTICLES_ID, lines=[line], metadata=metadata)]}


def quality_message(sample: dict) -> dict:
    """The ``/localisation/quality`` message (``beastbt.LocalisationQuality``) of a sample."""
    return {"match_quality": sample["match_quality"], "localized": sample["localized"],
            "updates": sample["updates"], "particles": sample["particle_count"]}


def contact_message(c: dict) -> dict:
    """The ``/sim/contact`` message (``beastbt.SimContact``) of a sampled contact."""
    return {"t_s": c["t_s"], "clearance_m": c["clearance_m"], "collisions": c["collisions"],
            "in_contact": c["in_contact"], "persons": c["persons"]}


__all__ = ["ObstacleSampler", "costmap_grid", "plan_update", "zones_update", "persons_update", "contact_message",
           "localisation_sample", "particles_update", "quality_message", "LOCALISATION_PERIOD_S", "PARTICLES_SHOWN",
           "board_reader", "fresh", "sim_contact", "zone_active", "COSTMAP_PERIOD_S", "VIEW_PERIOD_S", "STALE_S"]
