"""Contact between the robot's footprint and the world: walls, boxes, cylinders, walking persons and other robots.

The footprint is a circle of ``radius_m`` around the robot's centre (the
profile's ``footprint_radius_m``; a circle also stays the same shape when the
robot turns in place, so turning never causes or ends a contact). Every
question is asked about the robot's *centre* against the world inflated by
that radius: a wall becomes a capsule, a cylinder or a person a larger circle.

- :meth:`ContactWorld.free_fraction` is a swept test: which fraction of a
  straight move the robot can make before its footprint touches anything, so
  no speed or time step lets it tunnel through a thin wall. A robot that
  touches something may move along it or away from it, never into it.
- :meth:`ContactWorld.clearance` is the gap between the footprint and the
  nearest thing (negative inside), vectorised over every segment and circle.
- :meth:`ContactWorld.observe` keeps the run's truth: ``collisions`` (contact
  episodes, each counted once until the footprint is :data:`CLEAR_AFTER_M`
  clear of everything again) and ``min_clearance_m``.
- :meth:`ContactWorld.set_others` places the other robots of a shared world (circles of their footprints,
  where their own simulators last put them): the robot meets them as it meets a person; the persons here do
  not know them (they give way to this robot only).
- :meth:`ContactWorld.advance_persons` walks the persons. A person who gives
  way (the default) keeps its ``keeps_m`` from the robot's footprint, waits,
  and after ``patience_s`` steps around the robot on the side with room (walls
  and fixed obstacles respected), then rejoins its path; with no room on
  either side it waits on. One with ``gives_way: false`` walks until contact
  (it does not push) and walks on once it can.

How a person steps around: its place is a point of its path plus a sideways
offset (across the leg it is on, as the path is written, so the offset keeps
its side on the way back of a back-and-forth path). It waits while its next
step would come within ``keeps_m`` of the footprint; once it has waited
``patience_s`` it picks the offset that passes the robot ``keeps_m`` (plus
:data:`PASS_MARGIN_M`) away: on a side not ahead of where the robot faces,
then the side that needs the smaller step, then the person's right; a side
counts where the step sideways keeps half its ``keeps_m``
(:data:`STEP_ASIDE_KEEPS`) from the robot and the person fits
(:data:`ROOM_MARGIN_M` from walls and fixed obstacles) all along the step and
the pass. It steps sideways there at its walking speed, walks on beside the
robot, and once the robot is behind it drifts back onto its path. Every move
is checked against the robot where it is now (a swept circle test): walking,
a person's own move never brings it nearer than ``keeps_m``, stepping
sideways than half of it (a robot that came nearer may only be stepped away
from), so a person never walks into the robot, only a robot into a person.

Most physics steps need no geometry at all: after an exact clearance at some
place and time, the clearance anywhere else is at least that minus the distance
moved minus the farthest any person has walked since. Only when that
bound could matter (a move as long as it, a possible new minimum, a contact
episode to close) is the exact value computed.
"""

from __future__ import annotations

import math
from typing import Iterable, Optional, Sequence

import numpy as np

from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle, Obstacle, OtherRobot, Person

CONTACT_M: float = 1e-4
"""A gap at most this is a contact, m (the swept test leaves a touching robot at a gap of about 1e-12 m)."""

CLEAR_AFTER_M: float = 0.02
"""A contact episode ends when the footprint is more than this clear of everything, m (so a robot that
rocks against a wall counts one collision, not one per physics step)."""

SMALL_WORLD: int = 32
"""Up to this many walls and obstacles, :meth:`ContactWorld.clearance` and the swept test run in plain floats
(measured quicker than NumPy's cost per call up to about this many; benchmarks/sim_contact.py)."""

PASS_MARGIN_M: float = 0.02
"""A person passing the robot aims this much wider than its ``keeps_m`` (so walking past is not stopped by the
robot's own wobble of a few millimetres), m."""

STEP_ASIDE_KEEPS: float = 0.5
"""While it steps sideways a person keeps at least this fraction of its ``keeps_m`` from the footprint (the step out
from behind a robot it follows starts a little inside its personal distance, as people's do)."""

ROOM_MARGIN_M: float = 0.02
"""Where a person steps around the robot, it keeps at least this from walls and fixed obstacles, m."""

ROOM_STEP_M: float = 0.1
"""The room for a step around is checked at points this far apart along it, m."""

REJOIN_RATE: float = 0.5
"""Back onto its path, a person drifts sideways at this fraction of its walking speed (a gentle diagonal)."""

AHEAD_COS: float = 0.3
"""A place is ahead of the robot when the cosine of its bearing from the way the robot faces (or backs) is more than
this (within about 72 degrees): a person stepping around the robot prefers a side that is not."""

REJOIN_AHEAD_M: float = 1.0
"""A person beside its path drifts back onto it once the robot is behind it, or farther than its personal distance
plus this (a robot far ahead is not yet in the way), m."""

RETHINK_S: float = 0.5
"""A person with no room to step around looks again this often, s (it waits meanwhile)."""

_INF = math.inf


class ContactWorld:
    """The world's fixed geometry and its persons, as the robot's footprint of ``radius_m`` (m) meets them.

    ``walls`` are segments ``(x1, y1, x2, y2)`` in metres (anything with those attributes or a 4-sequence).
    """

    def __init__(self, walls: Iterable, obstacles: Sequence[Obstacle], radius_m: float) -> None:
        self.radius_m = float(radius_m)
        segs = [_segment(w) for w in walls]
        boxes = [o for o in obstacles if isinstance(o, BoxObstacle)]
        box_edges = [(*a, *b) for box in boxes for a, b in zip(box.corners(), box.corners()[1:] + box.corners()[:1])]
        self.wall_segments = np.array(segs, dtype=float).reshape(-1, 4)
        # The swept test meets a box at its edges (a robot outside can only get in through one); clearance uses
        # the box's signed distance, so a robot placed inside one is seen as inside.
        sweep_segs = np.array(segs + box_edges, dtype=float).reshape(-1, 4)
        lengths = np.hypot(sweep_segs[:, 2] - sweep_segs[:, 0], sweep_segs[:, 3] - sweep_segs[:, 1])
        keep = lengths > 1e-12  # a zero-length segment is only its end circles
        self._seg_a = sweep_segs[keep, :2]
        self._seg_len = lengths[keep]
        self._seg_u = (sweep_segs[keep, 2:] - self._seg_a) / self._seg_len[:, None] if keep.any() else np.zeros((0, 2))
        cyl = [o for o in obstacles if isinstance(o, CylinderObstacle)]
        self._circ_c = np.array([[o.x, o.y] for o in cyl] + [list(p) for s in sweep_segs for p in (s[:2], s[2:])],
                                dtype=float).reshape(-1, 2)
        self._circ_r = np.array([o.radius_m for o in cyl] + [0.0] * (2 * len(sweep_segs)), dtype=float) + self.radius_m
        self._n_cyl = len(cyl)
        self._box_c = np.array([[b.x, b.y] for b in boxes], dtype=float).reshape(-1, 2)
        self._box_cs = np.array([[math.cos(b.yaw), math.sin(b.yaw)] for b in boxes], dtype=float).reshape(-1, 2)
        self._box_h = np.array([[0.5 * b.length_m, 0.5 * b.width_m] for b in boxes], dtype=float).reshape(-1, 2)
        self._wall_a = self.wall_segments[:, :2]
        wall_d = self.wall_segments[:, 2:] - self._wall_a
        self._wall_d = wall_d
        self._wall_l2 = np.maximum(np.einsum("ij,ij->i", wall_d, wall_d), 1e-300)
        self.persons: list[Person] = [o for o in obstacles if isinstance(o, Person)]
        self.person_walked_m = [0.0] * len(self.persons)
        """How far each person has walked along its path, m."""
        self.person_xy = np.array([p.path[0] for p in self.persons], dtype=float).reshape(-1, 2)
        """Where each person is now (m, world frame)."""
        self._person_r = np.array([p.radius_m for p in self.persons], dtype=float) + self.radius_m
        self.person_offset_m = [0.0] * len(self.persons)
        """How far each person is beside its path, m (left of the leg it is on, as the path is written)."""
        self.person_waited_s = [0.0] * len(self.persons)
        """How long each person has been held up by the robot so far, s (0 while it walks freely)."""
        self.person_aside_to_m: list[Optional[float]] = [None] * len(self.persons)
        """The offset each person is stepping sideways to (m), or None when it is not stepping aside."""
        self._look_at_s = [p.patience_s for p in self.persons]  # waited this long, a person looks for a side, s
        self._robot_way = (0.0, 0.0)  # the unit vector of where the robot is going (it faces, or backs), world frame
        self._persons_moved_m = 0.0  # the most any person can have come closer since the last exact look, m
        self.collisions = 0
        """Distinct contact episodes so far."""
        self.min_clearance_m: Optional[float] = None
        """Smallest gap between the footprint and anything so far, m (None before the first look, or with nothing)."""
        self.in_contact = False
        """True from a contact until the footprint is CLEAR_AFTER_M clear again."""
        self.others: tuple[OtherRobot, ...] = ()
        """The other robots in the world now (:meth:`set_others`): circles the robot meets, moved from outside."""
        self.others_xy = np.zeros((0, 2))
        """Where each other robot is now (m, world frame), in the order of :attr:`others`."""
        self._others_r = np.zeros(0)  # each other robot's radius plus the footprint's, m
        self._fixed_empty = not (len(self.wall_segments) or boxes or cyl or self.persons)
        self.empty = self._fixed_empty
        self._walls_py = [(float(a[0]), float(a[1]), float(d[0]), float(d[1]), float(l2))
                          for a, d, l2 in zip(self._wall_a, self._wall_d, self._wall_l2)]
        self._cyl_py = [(o.x, o.y, o.radius_m) for o in cyl]
        self._box_py = [(b.x, b.y, math.cos(b.yaw), math.sin(b.yaw), 0.5 * b.length_m, 0.5 * b.width_m) for b in boxes]
        self._circ_py = [(float(c[0]), float(c[1]), float(r)) for c, r in zip(self._circ_c, self._circ_r)]
        self._seg_py = [(float(a[0]), float(a[1]), float(u[0]), float(u[1]), float(n))
                        for a, u, n in zip(self._seg_a, self._seg_u, self._seg_len)]
        self._n_things = len(self.wall_segments) + len(boxes) + len(cyl) + len(self.persons)
        self._small = self._n_things <= SMALL_WORLD
        self._ref: Optional[tuple[float, float, float]] = None  # (x, y, exact clearance) of the last look

    # -- other robots ------------------------------------------------------------
    def set_others(self, robots: Sequence[OtherRobot]) -> None:
        """The other robots are now ``robots`` (poses handed over between two physics steps, m and rad).

        The bound of the clearance stays valid when the same robots only moved (by the farthest any moved);
        another set of robots, or another footprint, asks for an exact look.
        """
        robots = tuple(robots)
        if robots == self.others:
            return
        before = {r.name: r for r in self.others}
        if (self._ref is not None and len(before) == len(robots)
                and all(r.name in before and before[r.name].radius_m == r.radius_m for r in robots)):
            self._persons_moved_m += max(math.hypot(r.x - before[r.name].x, r.y - before[r.name].y) for r in robots)
        else:
            self._ref = None
        self.others = robots
        self.others_xy = np.array([[r.x, r.y] for r in robots], dtype=float).reshape(-1, 2)
        self._others_r = np.array([r.radius_m for r in robots], dtype=float) + self.radius_m
        self.empty = self._fixed_empty and not robots
        self._small = self._n_things + len(robots) <= SMALL_WORLD

    # -- geometry -----------------------------------------------------------------
    def clearance(self, x: float, y: float) -> float:
        """Gap between the footprint at (x, y) and the nearest wall or obstacle now, m (negative inside; inf if none).

        Vectorised over every wall, box, cylinder and person; a small world (a corridor's walls, a few obstacles)
        is quicker in plain floats, where NumPy's cost per call would outweigh the work.
        """
        if self._small:
            return self._clearance_small(x, y)
        return self._clearance_numpy(x, y)

    def fixed_distance(self, x: float, y: float) -> float:
        """Distance from the point (x, y) to the nearest wall, box or cylinder, m (negative inside a box; inf if none).

        What a person stepping around the robot keeps clear of (the robot and the persons are not counted).
        """
        if self._small:
            return self._fixed_small(x, y)
        return self._fixed_numpy(x, y)

    def _clearance_small(self, x: float, y: float) -> float:
        """:meth:`clearance` in plain floats, one thing at a time."""
        best = self._fixed_small(x, y)
        for (px, py), person in zip(self.person_xy.tolist(), self.persons):
            best = min(best, math.hypot(x - px, y - py) - person.radius_m)
        for other in self.others:
            best = min(best, math.hypot(x - other.x, y - other.y) - other.radius_m)
        return best - self.radius_m

    def _fixed_small(self, x: float, y: float) -> float:
        """:meth:`fixed_distance` in plain floats."""
        best = _INF
        for ax, ay, dx, dy, l2 in self._walls_py:
            rx, ry = x - ax, y - ay
            t = min(1.0, max(0.0, (rx * dx + ry * dy) / l2))
            best = min(best, math.hypot(rx - t * dx, ry - t * dy))
        for cx, cy, r in self._cyl_py:
            best = min(best, math.hypot(x - cx, y - cy) - r)
        for cx, cy, c, s, hx, hy in self._box_py:
            rx, ry = x - cx, y - cy
            lx, ly = abs(rx * c + ry * s) - hx, abs(-rx * s + ry * c) - hy
            best = min(best, math.hypot(max(lx, 0.0), max(ly, 0.0)) + min(max(lx, ly), 0.0))
        return best

    def _clearance_numpy(self, x: float, y: float) -> float:
        """:meth:`clearance` vectorised over each kind of thing."""
        best = self._fixed_numpy(x, y)
        if len(self.persons):
            d = np.hypot(self.person_xy[:, 0] - x, self.person_xy[:, 1] - y) - self._person_r
            best = min(best, float(d.min()) + self.radius_m)
        if self.others:
            d = np.hypot(self.others_xy[:, 0] - x, self.others_xy[:, 1] - y) - self._others_r
            best = min(best, float(d.min()) + self.radius_m)
        return best - self.radius_m

    def _fixed_numpy(self, x: float, y: float) -> float:
        """:meth:`fixed_distance` vectorised over each kind of thing."""
        best = _INF
        if len(self._wall_a):
            rel = np.array((x, y)) - self._wall_a
            t = np.clip(np.einsum("ij,ij->i", rel, self._wall_d) / self._wall_l2, 0.0, 1.0)
            off = rel - t[:, None] * self._wall_d
            best = float(np.sqrt(np.einsum("ij,ij->i", off, off).min()))
        if self._n_cyl:
            n = self._n_cyl
            d = np.hypot(self._circ_c[:n, 0] - x, self._circ_c[:n, 1] - y) - self._circ_r[:n]
            best = min(best, float(d.min()) + self.radius_m)
        if len(self._box_c):
            rel = np.array((x, y)) - self._box_c
            lx = np.abs(rel[:, 0] * self._box_cs[:, 0] + rel[:, 1] * self._box_cs[:, 1]) - self._box_h[:, 0]
            ly = np.abs(-rel[:, 0] * self._box_cs[:, 1] + rel[:, 1] * self._box_cs[:, 0]) - self._box_h[:, 1]
            sdf = np.hypot(np.maximum(lx, 0.0), np.maximum(ly, 0.0)) + np.minimum(np.maximum(lx, ly), 0.0)
            best = min(best, float(sdf.min()))
        return best

    def free_fraction(self, x0: float, y0: float, x1: float, y1: float) -> float:
        """The fraction (0 to 1) of the straight move from (x0, y0) to (x1, y1) (m) the footprint makes before contact.

        1.0 means the whole move is free. The persons stand where they are for it (they walk before the robot moves).
        """
        step = math.hypot(x1 - x0, y1 - y0)
        if step == 0.0 or self.empty:
            return 1.0
        if self._bound(x0, y0) > step:
            return 1.0
        gap = self._look(x0, y0)
        if gap > step:
            return 1.0
        s = self._sweep_small(x0, y0, x1 - x0, y1 - y0) if self._small else self._sweep_numpy(x0, y0, x1, y1)
        return 1.0 if s > 1.0 else max(0.0, s)

    def _sweep_small(self, x0: float, y0: float, dx: float, dy: float) -> float:
        """The swept test in plain floats: the first fraction of the move at which anything is met (inf: none)."""
        s = _INF
        for cx, cy, r in self._circ_py:
            s = min(s, _sweep_circle(x0, y0, dx, dy, cx, cy, r))
        for (px, py), r in zip(self.person_xy.tolist(), self._person_r.tolist()):
            s = min(s, _sweep_circle(x0, y0, dx, dy, px, py, r))
        for (px, py), r in zip(self.others_xy.tolist(), self._others_r.tolist()):
            s = min(s, _sweep_circle(x0, y0, dx, dy, px, py, r))
        radius = self.radius_m
        for ax, ay, ux, uy, length in self._seg_py:
            rx, ry = x0 - ax, y0 - ay
            along, across = rx * ux + ry * uy, ux * ry - uy * rx
            d_along, d_across = ux * dx + uy * dy, ux * dy - uy * dx
            if abs(across) <= radius and 0.0 <= along <= length:  # already touching its straight part
                if across * d_across < 0.0:
                    return 0.0
                continue
            if abs(across) > radius and across * d_across < 0.0:
                t = (abs(across) - radius) / abs(d_across)
                if t <= 1.0 and 0.0 <= along + t * d_along <= length:
                    s = min(s, t)
        return s

    def _sweep_numpy(self, x0: float, y0: float, x1: float, y1: float) -> float:
        """The swept test vectorised over every segment and circle (inf: nothing met)."""
        p0 = np.array((x0, y0))
        d = np.array((x1 - x0, y1 - y0))
        s = _INF
        if len(self._circ_c):
            s = min(s, float(_sweep_circles(p0, d, self._circ_c, self._circ_r).min()))
        if len(self._seg_a):
            s = min(s, float(_sweep_slabs(p0, d, self._seg_a, self._seg_u, self._seg_len, self.radius_m).min()))
        if len(self.persons):
            s = min(s, float(_sweep_circles(p0, d, self.person_xy, self._person_r).min()))
        if self.others:
            s = min(s, float(_sweep_circles(p0, d, self.others_xy, self._others_r).min()))
        return s

    # -- persons ------------------------------------------------------------------
    def advance_persons(self, t_s: float, dt_s: float, robot_x: float, robot_y: float,
                        robot_yaw: Optional[float] = None, robot_v_mps: float = 0.0) -> None:
        """Walk every person for the step of ``dt_s`` ending at ``t_s`` (s), around the robot at
        (``robot_x``, ``robot_y``) (m) facing ``robot_yaw`` (rad; None: unknown) and driving at ``robot_v_mps``
        (m/s, negative backwards): as the module docstring says, giving way, or with ``gives_way: false`` stopping
        at contact.

        A person held up by the robot walks on from where it is, at its own speed (it does not run to catch up
        with its timetable).
        """
        farthest = 0.0
        if robot_yaw is None:
            self._robot_way = (0.0, 0.0)
        else:
            way = -1.0 if robot_v_mps < 0.0 else 1.0
            self._robot_way = (way * math.cos(robot_yaw), way * math.sin(robot_yaw))
        for i, person in enumerate(self.persons):
            walking_s = min(dt_s, t_s - person.start_s)
            if walking_s <= 0.0 or person.speed_mps <= 0.0:
                continue
            if person.gives_way:
                moved = self._give_way(i, person, walking_s, robot_x, robot_y)
            else:
                moved = self._walk_into(i, person, walking_s, robot_x, robot_y)
            farthest = max(farthest, moved)
        self._persons_moved_m += farthest  # the bound: no person came closer than this since the last look

    def _walk_into(self, i: int, person: Person, dt_s: float, robot_x: float, robot_y: float) -> float:
        """One step of a person who does not give way: on along its path until contact. Returns how far it moved, m."""
        walked = self.person_walked_m[i]
        if not person.loop and walked >= person.length_m:
            return 0.0  # standing at its end for good
        target = walked + person.speed_mps * dt_s
        qx, qy = float(self.person_xy[i, 0]), float(self.person_xy[i, 1])
        nx, ny = person.point_at(target)
        s = _sweep_circle(qx, qy, nx - qx, ny - qy, robot_x, robot_y, person.radius_m + self.radius_m)
        s = min(s, 1.0)  # below 1: it stops at the robot, as far along as it got
        self.person_walked_m[i] = walked + s * (target - walked)
        self.person_xy[i, 0], self.person_xy[i, 1] = qx + s * (nx - qx), qy + s * (ny - qy)
        return s * math.hypot(nx - qx, ny - qy)

    def _person_at(self, person: Person, walked_m: float, offset_m: float) -> tuple[float, float]:
        """Where a person is after ``walked_m`` along its path and ``offset_m`` beside it (m, world frame)."""
        x, y, ux, uy, _ = person.place_at(walked_m)
        return x - offset_m * uy, y + offset_m * ux

    def _fits(self, person: Person, x: float, y: float, walked_m: float) -> bool:
        """Whether a person off its path at (x, y) (m) is clear of walls and fixed obstacles: by
        :data:`ROOM_MARGIN_M`, or at least as clear as its path is there (a path that runs close to a wall)."""
        need = person.radius_m + ROOM_MARGIN_M
        gap = self.fixed_distance(x, y)
        if gap >= need:
            return True
        px, py = person.point_at(walked_m)
        return gap >= min(need, self.fixed_distance(px, py))

    def _give_way(self, i: int, person: Person, dt_s: float, robot_x: float, robot_y: float) -> float:
        """One step of a person who gives way to the robot. Returns how far it moved, m."""
        walked, offset = self.person_walked_m[i], self.person_offset_m[i]
        qx, qy = float(self.person_xy[i, 0]), float(self.person_xy[i, 1])
        step = person.speed_mps * dt_s
        touch = person.radius_m + self.radius_m
        aside = self.person_aside_to_m[i]
        if offset == 0.0 and aside is None and (person.loop or walked < person.length_m):
            # The common case, on its path with the robot out of reach of this step: no more than before persons
            # gave way (one point of the path, one distance).
            reach = touch + person.keeps_m + step
            if (qx - robot_x) ** 2 + (qy - robot_y) ** 2 > reach * reach:
                ahead = walked + step if person.loop else min(walked + step, person.length_m)
                x, y = person.point_at(ahead)
                self.person_waited_s[i] = 0.0
                self._look_at_s[i] = person.patience_s
                return self._move(i, ahead, x, y, qx, qy)
        if aside is not None:  # stepping sideways, out of the robot's way
            o = _toward(offset, aside, step)
            x, y = self._person_at(person, walked, o)
            # Most of its personal distance holds here too; a robot that came nearer may only be stepped away from.
            if (_sweep_circle(qx, qy, x - qx, y - qy, robot_x, robot_y, touch + STEP_ASIDE_KEEPS * person.keeps_m) > 1.0
                    and self._fits(person, x, y, walked)):
                self.person_offset_m[i] = o
                if o == aside:  # out of the way: walk on beside the robot (and wait afresh if it is still there)
                    self.person_aside_to_m[i] = None
                    self.person_waited_s[i] = 0.0
                    self._look_at_s[i] = person.patience_s
                return self._move(i, walked, x, y, qx, qy)
            # The robot moved into the way of the step: wait, and look for a side again a little later.
            self.person_aside_to_m[i] = None
            self.person_waited_s[i] += dt_s
            self._look_at_s[i] = self.person_waited_s[i] + RETHINK_S
            return 0.0
        keep = touch + person.keeps_m
        if not person.loop and walked >= person.length_m:  # at its end: back onto it if it can, then stands
            if offset == 0.0:
                return 0.0
            o = _toward(offset, 0.0, REJOIN_RATE * step)
            x, y = self._person_at(person, walked, o)
            if _sweep_circle(qx, qy, x - qx, y - qy, robot_x, robot_y, keep) > 1.0 and self._fits(person, x, y, walked):
                self.person_offset_m[i] = o
                return self._move(i, walked, x, y, qx, qy)
            return 0.0
        ahead = walked + step if person.loop else min(walked + step, person.length_m)
        candidates = []
        if offset != 0.0 and self._may_rejoin(person, walked, offset, keep, robot_x, robot_y):
            candidates.append((ahead, _toward(offset, 0.0, REJOIN_RATE * step)))  # drift back onto the path
        candidates.append((ahead, offset))
        for n, (w, o) in enumerate(candidates):
            x, y = self._person_at(person, w, o)
            s = _sweep_circle(qx, qy, x - qx, y - qy, robot_x, robot_y, keep)
            if o != 0.0 and not self._fits(person, x, y, w):
                continue
            if s > 1.0:
                self.person_offset_m[i] = o
                self.person_waited_s[i] = 0.0
                self._look_at_s[i] = person.patience_s
                return self._move(i, w, x, y, qx, qy)
            if n == len(candidates) - 1 and s > 0.0:
                # Held up: as far as its personal distance allows (it stops keeps_m from the robot).
                w = walked + s * (w - walked)
                x, y = self._person_at(person, w, o)
                self._move(i, w, x, y, qx, qy)
                self._held(i, person, dt_s, robot_x, robot_y)
                return math.hypot(x - qx, y - qy)
        return self._held(i, person, dt_s, robot_x, robot_y)

    def _move(self, i: int, walked_m: float, x: float, y: float, qx: float, qy: float) -> float:
        """Put person ``i`` at (x, y) (m), ``walked_m`` along its path, from (qx, qy); returns how far it moved, m."""
        self.person_walked_m[i] = walked_m
        self.person_xy[i, 0], self.person_xy[i, 1] = x, y
        return math.hypot(x - qx, y - qy)

    def _held(self, i: int, person: Person, dt_s: float, robot_x: float, robot_y: float) -> float:
        """Person ``i`` is held up by the robot for ``dt_s`` (s): once it has waited its patience it picks a side to
        step around to, or, with no room on either, waits and looks again after :data:`RETHINK_S`. Returns 0 (m)."""
        waited = self.person_waited_s[i] + dt_s
        self.person_waited_s[i] = waited
        if waited >= self._look_at_s[i]:
            side = self._side_with_room(i, person, robot_x, robot_y)
            if side is None:
                self._look_at_s[i] = waited + RETHINK_S
            else:
                self.person_aside_to_m[i] = side
        return 0.0

    def _may_rejoin(self, person: Person, walked_m: float, offset_m: float, keep_m: float,
                    robot_x: float, robot_y: float) -> bool:
        """Whether a person beside its path may drift back onto it: once the robot is behind it (seen along the way
        it walks), or more than :data:`REJOIN_AHEAD_M` beyond its personal distance (``keep_m``, centre to centre)."""
        x, y, ux, uy, way = person.place_at(walked_m)
        x, y = x - offset_m * uy, y + offset_m * ux
        if math.hypot(robot_x - x, robot_y - y) > keep_m + REJOIN_AHEAD_M:
            return True
        return ((robot_x - x) * ux + (robot_y - y) * uy) * way < 0.0

    def _side_with_room(self, i: int, person: Person, robot_x: float, robot_y: float) -> Optional[float]:
        """The offset (m) person ``i`` steps to so as to pass the robot at (robot_x, robot_y), or None: no room.

        Of the offsets that pass it ``keeps_m`` + :data:`PASS_MARGIN_M` away on either side: one not ahead of the
        robot (within :data:`AHEAD_COS` of the way it faces, or backs; a robot held by its collision monitor still
        faces where it is going), then the nearer, then the person's right; among those where the step sideways
        comes no nearer the robot than :data:`STEP_ASIDE_KEEPS` of ``keeps_m`` (or than it is, when the robot came
        nearer) and the person fits (:meth:`_fits`) all along the step and the pass.
        """
        walked, offset = self.person_walked_m[i], self.person_offset_m[i]
        bx, by, ux, uy, way = person.place_at(walked)
        touch = person.radius_m + self.radius_m
        lateral = -(robot_x - bx) * uy + (robot_y - by) * ux  # the robot's offset from the path here, m
        along = ((robot_x - bx) * ux + (robot_y - by) * uy) * way  # how far ahead of the person it is, m
        pass_m = touch + person.keeps_m + PASS_MARGIN_M
        qx, qy = float(self.person_xy[i, 0]), float(self.person_xy[i, 1])
        best: Optional[tuple[float, int, float]] = None
        for side in (1.0, -1.0):
            target = lateral + side * pass_m
            tx, ty = self._person_at(person, walked, target)
            near = min(touch + STEP_ASIDE_KEEPS * person.keeps_m, math.hypot(robot_x - qx, robot_y - qy))
            if _segment_distance(robot_x, robot_y, qx, qy, tx, ty) < near - 1e-9:
                continue  # the step would come too near the robot (or nearer to a robot already that near)
            if not self._room_along(person, walked, offset, target, max(0.0, along) + pass_m):
                continue
            hx, hy = self._robot_way
            in_front = (tx - robot_x) * hx + (ty - robot_y) * hy > AHEAD_COS * math.hypot(tx - robot_x, ty - robot_y)
            rank = (in_front, abs(target - offset), 0 if side == -way else 1, target)  # -way: the person's right
            if best is None or rank < best:
                best = rank
        return None if best is None else best[-1]

    def _room_along(self, person: Person, walked_m: float, offset_m: float, target_m: float, pass_m: float) -> bool:
        """Whether a person fits all along a step sideways from ``offset_m`` to ``target_m`` at ``walked_m`` and on
        for ``pass_m`` at ``target_m`` (m), looked at every :data:`ROOM_STEP_M`."""
        n = max(1, math.ceil(abs(target_m - offset_m) / ROOM_STEP_M))
        for k in range(1, n + 1):
            o = offset_m + (target_m - offset_m) * k / n
            if not self._fits(person, *self._person_at(person, walked_m, o), walked_m):
                return False
        end = walked_m + pass_m
        if not person.loop:
            end = min(end, person.length_m)
        n = math.ceil((end - walked_m) / ROOM_STEP_M)
        for k in range(1, n + 1):
            w = walked_m + (end - walked_m) * k / n
            if not self._fits(person, *self._person_at(person, w, target_m), w):
                return False
        return True

    # -- truth --------------------------------------------------------------------
    def observe(self, x: float, y: float) -> None:
        """Update ``collisions``, ``in_contact`` and ``min_clearance_m`` with the robot now at (x, y) (m)."""
        if self.empty:
            return
        bound = self._bound(x, y)
        least = self.min_clearance_m
        if (least is not None and bound >= least and bound > CONTACT_M
                and not (self.in_contact and bound <= CLEAR_AFTER_M)):
            return  # nothing new can be learnt here: no new minimum, no contact, no episode to close
        gap = self._look(x, y)
        if least is None or gap < least:
            self.min_clearance_m = gap
        if gap <= CONTACT_M:
            if not self.in_contact:
                self.collisions += 1
            self.in_contact = True
        elif gap > CLEAR_AFTER_M:
            self.in_contact = False

    def _look(self, x: float, y: float) -> float:
        """The exact clearance at (x, y) now, remembered as the reference of the bound."""
        gap = self.clearance(x, y)
        self._ref = (x, y, gap)
        self._persons_moved_m = 0.0
        return gap

    def _bound(self, x: float, y: float) -> float:
        """A lower bound of the clearance at (x, y) now from the last exact look (m; -inf without one): the
        clearance then, less how far the robot is from there and how far the persons have walked since."""
        if self._ref is None:
            return -_INF
        rx, ry, gap = self._ref
        return gap - math.hypot(x - rx, y - ry) - self._persons_moved_m


def _segment(w: object) -> tuple[float, float, float, float]:
    """(x1, y1, x2, y2) of a wall given as an object with those attributes or as a sequence of four numbers."""
    if hasattr(w, "x1"):
        return float(w.x1), float(w.y1), float(w.x2), float(w.y2)  # type: ignore[attr-defined]
    x1, y1, x2, y2 = w  # type: ignore[misc]
    return float(x1), float(y1), float(x2), float(y2)


def _toward(value: float, target: float, step: float) -> float:
    """``value`` moved toward ``target`` by at most ``step`` (landing on it exactly)."""
    if abs(target - value) <= step:
        return target
    return value + step if target > value else value - step


def _segment_distance(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    """Distance from the point (px, py) to the segment from (ax, ay) to (bx, by), m."""
    dx, dy = bx - ax, by - ay
    l2 = dx * dx + dy * dy
    t = 0.0 if l2 == 0.0 else min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy) / l2))
    return math.hypot(px - ax - t * dx, py - ay - t * dy)


def _sweep_circle(x0: float, y0: float, dx: float, dy: float, cx: float, cy: float, radius: float) -> float:
    """:func:`_sweep_circles` for one circle, in plain floats (a person's step against the robot, every step)."""
    a = dx * dx + dy * dy
    if a == 0.0:
        return _INF
    fx, fy = x0 - cx, y0 - cy
    b = 2.0 * (fx * dx + fy * dy)
    c = fx * fx + fy * fy - radius * radius
    if c <= 0.0:
        return 0.0 if b < 0.0 else _INF
    disc = b * b - 4.0 * a * c
    if disc < 0.0 or b >= 0.0:
        return _INF
    s = (-b - math.sqrt(disc)) / (2.0 * a)
    return max(s, 0.0) if s <= 1.0 else _INF


def _sweep_circles(p0: np.ndarray, d: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """For each circle, the fraction of the move p0 -> p0 + d at which the point p enters it (inf: never).

    A point already inside or on a circle is stopped at once (0) only if it moves inwards; moving along or out is free.
    """
    f = p0 - centres
    a = float(d @ d)
    b = 2.0 * (f @ d)
    c = np.einsum("ij,ij->i", f, f) - radii * radii
    inside = c <= 0.0
    disc = b * b - 4.0 * a * c
    s = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
    hit = ~inside & (disc >= 0.0) & (b < 0.0) & (s <= 1.0)
    return np.where(inside, np.where(b < 0.0, 0.0, _INF), np.where(hit, np.maximum(s, 0.0), _INF))


def _sweep_slabs(p0: np.ndarray, d: np.ndarray, a: np.ndarray, u: np.ndarray, length: np.ndarray,
                 radius: float) -> np.ndarray:
    """For each segment, the fraction of the move at which p comes within ``radius`` of its straight part (inf: never).

    The segment's ends are circles of their own (:func:`_sweep_circles`); together they make the capsule.
    """
    rel = p0 - a
    x0 = np.einsum("ij,ij->i", rel, u)
    y0 = u[:, 0] * rel[:, 1] - u[:, 1] * rel[:, 0]
    dx = u @ d
    dy = u[:, 0] * d[1] - u[:, 1] * d[0]
    along = (x0 >= 0.0) & (x0 <= length)
    inside = (np.abs(y0) <= radius) & along
    towards = np.sign(y0) * dy < 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (np.abs(y0) - radius) / np.abs(dy)
    xs = x0 + s * dx
    hit = (np.abs(y0) > radius) & towards & (s <= 1.0) & (xs >= 0.0) & (xs <= length)
    return np.where(inside, np.where(y0 * dy < 0.0, 0.0, _INF), np.where(hit, s, _INF))


__all__ = ["ContactWorld", "CONTACT_M", "CLEAR_AFTER_M", "PASS_MARGIN_M", "STEP_ASIDE_KEEPS", "ROOM_MARGIN_M",
           "ROOM_STEP_M", "REJOIN_RATE", "REJOIN_AHEAD_M", "RETHINK_S", "AHEAD_COS"]
