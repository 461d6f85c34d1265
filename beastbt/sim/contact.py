"""Contact between the robot's footprint and the world: walls, boxes, cylinders and walking persons.

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
- :meth:`ContactWorld.advance_persons` walks the persons; one who would walk
  into the robot stops at contact (it does not push) and walks on once it can.

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

from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle, Obstacle, Person

CONTACT_M: float = 1e-4
"""A gap at most this is a contact, m (the swept test leaves a touching robot at a gap of about 1e-12 m)."""

CLEAR_AFTER_M: float = 0.02
"""A contact episode ends when the footprint is more than this clear of everything, m (so a robot that
rocks against a wall counts one collision, not one per physics step)."""

SMALL_WORLD: int = 32
"""Up to this many walls and obstacles, :meth:`ContactWorld.clearance` and the swept test run in plain floats
(measured quicker than NumPy's cost per call up to about this many; benchmarks/sim_contact.py)."""

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
        self._persons_moved_m = 0.0  # the most any person can have come closer since the last exact look, m
        self.collisions = 0
        """Distinct contact episodes so far."""
        self.min_clearance_m: Optional[float] = None
        """Smallest gap between the footprint and anything so far, m (None before the first look, or with nothing)."""
        self.in_contact = False
        """True from a contact until the footprint is CLEAR_AFTER_M clear again."""
        self.empty = not (len(self.wall_segments) or boxes or cyl or self.persons)
        self._walls_py = [(float(a[0]), float(a[1]), float(d[0]), float(d[1]), float(l2))
                          for a, d, l2 in zip(self._wall_a, self._wall_d, self._wall_l2)]
        self._cyl_py = [(o.x, o.y, o.radius_m) for o in cyl]
        self._box_py = [(b.x, b.y, math.cos(b.yaw), math.sin(b.yaw), 0.5 * b.length_m, 0.5 * b.width_m) for b in boxes]
        self._circ_py = [(float(c[0]), float(c[1]), float(r)) for c, r in zip(self._circ_c, self._circ_r)]
        self._seg_py = [(float(a[0]), float(a[1]), float(u[0]), float(u[1]), float(n))
                        for a, u, n in zip(self._seg_a, self._seg_u, self._seg_len)]
        self._small = len(self.wall_segments) + len(boxes) + len(cyl) + len(self.persons) <= SMALL_WORLD
        self._ref: Optional[tuple[float, float, float]] = None  # (x, y, exact clearance) of the last look

    # -- geometry -----------------------------------------------------------------
    def clearance(self, x: float, y: float) -> float:
        """Gap between the footprint at (x, y) and the nearest wall or obstacle now, m (negative inside; inf if none).

        Vectorised over every wall, box, cylinder and person; a small world (a corridor's walls, a few obstacles)
        is quicker in plain floats, where NumPy's cost per call would outweigh the work.
        """
        if self._small:
            return self._clearance_small(x, y)
        return self._clearance_numpy(x, y)

    def _clearance_small(self, x: float, y: float) -> float:
        """:meth:`clearance` in plain floats, one thing at a time."""
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
        for (px, py), person in zip(self.person_xy.tolist(), self.persons):
            best = min(best, math.hypot(x - px, y - py) - person.radius_m)
        return best - self.radius_m

    def _clearance_numpy(self, x: float, y: float) -> float:
        """:meth:`clearance` vectorised over each kind of thing."""
        best = _INF
        if len(self._wall_a):
            rel = np.array((x, y)) - self._wall_a
            t = np.clip(np.einsum("ij,ij->i", rel, self._wall_d) / self._wall_l2, 0.0, 1.0)
            off = rel - t[:, None] * self._wall_d
            best = float(np.sqrt(np.einsum("ij,ij->i", off, off).min()))
        if self._n_cyl:
            d = np.hypot(self._circ_c[:self._n_cyl, 0] - x, self._circ_c[:self._n_cyl, 1] - y) - self._circ_r[:self._n_cyl]
            best = min(best, float(d.min()) + self.radius_m)
        if len(self._box_c):
            rel = np.array((x, y)) - self._box_c
            lx = np.abs(rel[:, 0] * self._box_cs[:, 0] + rel[:, 1] * self._box_cs[:, 1]) - self._box_h[:, 0]
            ly = np.abs(-rel[:, 0] * self._box_cs[:, 1] + rel[:, 1] * self._box_cs[:, 0]) - self._box_h[:, 1]
            sdf = np.hypot(np.maximum(lx, 0.0), np.maximum(ly, 0.0)) + np.minimum(np.maximum(lx, ly), 0.0)
            best = min(best, float(sdf.min()))
        if len(self.persons):
            d = np.hypot(self.person_xy[:, 0] - x, self.person_xy[:, 1] - y) - self._person_r
            best = min(best, float(d.min()) + self.radius_m)
        return best - self.radius_m

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
        return s

    # -- persons ------------------------------------------------------------------
    def advance_persons(self, t_s: float, dt_s: float, robot_x: float, robot_y: float) -> None:
        """Walk every person for the step of ``dt_s`` ending at ``t_s`` (s), stopping at contact with the robot at
        (``robot_x``, ``robot_y``) (m).

        A person held up by the robot walks on from where it stopped, at its own speed (it does not run to catch up
        with its timetable).
        """
        farthest = 0.0
        for i, person in enumerate(self.persons):
            walking_s = min(dt_s, t_s - person.start_s)
            if walking_s <= 0.0 or person.speed_mps <= 0.0:
                continue
            walked = self.person_walked_m[i]
            if not person.loop and walked >= person.length_m:
                continue  # standing at its end for good
            target = walked + person.speed_mps * walking_s
            qx, qy = float(self.person_xy[i, 0]), float(self.person_xy[i, 1])
            nx, ny = person.point_at(target)
            s = _sweep_circle(qx, qy, nx - qx, ny - qy, robot_x, robot_y, person.radius_m + self.radius_m)
            s = min(s, 1.0)  # below 1: it stops at the robot, as far along as it got
            self.person_walked_m[i] = walked + s * (target - walked)
            self.person_xy[i, 0], self.person_xy[i, 1] = qx + s * (nx - qx), qy + s * (ny - qy)
            farthest = max(farthest, s * math.hypot(nx - qx, ny - qy))
        self._persons_moved_m += farthest  # the bound: no person came closer than this since the last look

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


__all__ = ["ContactWorld", "CONTACT_M", "CLEAR_AFTER_M"]
