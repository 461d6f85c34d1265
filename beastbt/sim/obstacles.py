"""Obstacles of a simulated world: fixed boxes and cylinders, persons who walk a path, and other robots.

A world's ``obstacles:`` list (``schemas/world.schema.json``) becomes these
plain records; positions are metres in the world's local east-north-up frame,
yaw radians counter-clockwise from east. This module has no NumPy, so checking
a world stays light; the contact geometry that uses these records is in
:mod:`beastbt.sim.contact`.

A person stands at its path's first point until ``start_s``, then walks the
path at ``speed_mps``. With ``loop: false`` it stands at the end for good. With
``loop: true`` it walks for ever: around again when the path is closed (its
last point is its first), else back and forth along it. Where it is depends on
how far it has walked (:meth:`Person.point_at`), not on the clock alone, because
a person who meets the robot waits, or steps around it, and walks on later.

A person gives way to the robot as people do (``gives_way``, the default): it
keeps ``keeps_m`` between itself and the robot's footprint, waits, and when the
robot stays in its way for ``patience_s`` steps around it on the side with
room, then rejoins its path. With ``gives_way: false`` it walks on until it
touches the robot (a test of the robot's own collision monitor). What a person
does from step to step is in :class:`beastbt.sim.contact.ContactWorld`, which
knows the robot, the walls and the fixed obstacles; here are only the records
and the geometry of the path.

Other robots (:class:`OtherRobot`) share the world when robots are simulated
side by side on a fleet: each robot's simulator is told where the others are
(:class:`OtherRobots`, the hand-over from the fleet's thread), and sees them
as circles of their footprint that its LiDAR draws and its robot can touch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
import threading
import time
from typing import Any, Callable, Iterable, Optional, Union

from beastbt.core.schema_defaults import schema_default

CLOSED_PATH_TOLERANCE_M: float = 1e-6
"""A path whose last point is within this of its first is closed (a person with ``loop: true`` walks around it), m."""


@dataclass(frozen=True)
class BoxObstacle:
    """A fixed box: centre ``x``, ``y`` (m), ``length_m`` along its own x, ``width_m`` along its y, ``yaw`` (rad)."""

    x: float
    y: float
    length_m: float
    width_m: float
    yaw: float = 0.0
    colour: Optional[str] = None
    """Its paint as the camera sees it (``red``, ``green``, ``blue``, ``yellow``); None: brown cardboard."""

    def corners(self) -> list[tuple[float, float]]:
        """The four corners in the world frame (m), counter-clockwise."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        hx, hy = 0.5 * self.length_m, 0.5 * self.width_m
        return [(self.x + c * px - s * py, self.y + s * px + c * py)
                for px, py in ((hx, hy), (-hx, hy), (-hx, -hy), (hx, -hy))]


@dataclass(frozen=True)
class CylinderObstacle:
    """A fixed upright cylinder (a post, a tree): centre ``x``, ``y`` and ``radius_m`` (m)."""

    x: float
    y: float
    radius_m: float


@dataclass(frozen=True)
class Person:
    """A person seen from above as a circle of ``radius_m`` (m) who walks ``path`` (m) at ``speed_mps`` (m/s).

    It sets off at ``start_s`` (s of simulated time); ``loop`` as the module docstring says. ``gives_way``: it keeps
    ``keeps_m`` (m) between itself and the robot's footprint and steps around a robot that stays in its way for
    ``patience_s`` (s); False: it walks until it touches the robot. The defaults are the world schema's.
    """

    radius_m: float
    speed_mps: float
    path: tuple[tuple[float, float], ...]
    start_s: float = 0.0
    loop: bool = False
    keeps_m: float = 0.3
    patience_s: float = 1.5
    gives_way: bool = True

    @cached_property
    def legs_m(self) -> tuple[float, ...]:
        """Length of each leg of the path, m."""
        return tuple(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(self.path, self.path[1:]))

    @cached_property
    def length_m(self) -> float:
        """Length of the path, m."""
        return sum(self.legs_m)

    @cached_property
    def closed(self) -> bool:
        """True when the path ends where it starts (and has somewhere to go)."""
        return (len(self.path) > 2 and self.length_m > 0
                and math.hypot(self.path[-1][0] - self.path[0][0], self.path[-1][1] - self.path[0][1])
                <= CLOSED_PATH_TOLERANCE_M)

    @cached_property
    def _legs(self) -> tuple[tuple[float, float, float, float, float, float, float], ...]:
        """``(ax, ay, dx, dy, length, ux, uy)`` of each leg of some length (m; u the unit vector along it)."""
        return tuple((a[0], a[1], b[0] - a[0], b[1] - a[1], leg, (b[0] - a[0]) / leg, (b[1] - a[1]) / leg)
                     for a, b, leg in zip(self.path, self.path[1:], self.legs_m) if leg > 0)

    def walked_by(self, t_s: float) -> float:
        """How far the person has walked at ``t_s`` if nothing stopped it, m."""
        return max(0.0, t_s - self.start_s) * self.speed_mps

    def point_at(self, walked_m: float) -> tuple[float, float]:
        """Where the person is after walking ``walked_m`` metres from the path's start (m, world frame)."""
        x, y, _, _, _ = self.place_at(walked_m)
        return x, y

    def place_at(self, walked_m: float) -> tuple[float, float, float, float, float]:
        """``(x, y, ux, uy, way)`` after walking ``walked_m`` metres: where (m, world frame), the unit vector of the
        leg it is on as the path is written, and ``way`` +1 when it walks that leg forwards, -1 backwards (the
        way back of a back-and-forth loop). A path of one point, or of no length, has the leg (1, 0)."""
        length = self.length_m
        if length <= 0.0:
            return self.path[0][0], self.path[0][1], 1.0, 0.0, 1.0
        way = 1.0
        if walked_m >= length:
            if not self.loop:
                last = self._legs[-1]
                return self.path[-1][0], self.path[-1][1], last[5], last[6], 1.0  # its last point, exactly
            if self.closed:
                walked_m = math.fmod(walked_m, length)
            else:  # back and forth: odd laps walk the path backwards
                lap, along = divmod(walked_m, length)
                if int(lap) % 2 == 0:
                    walked_m = along
                else:
                    walked_m, way = length - along, -1.0
        elif walked_m < 0.0:
            walked_m = 0.0
        for ax, ay, dx, dy, leg, ux, uy in self._legs:
            if walked_m <= leg:
                f = walked_m / leg
                return ax + f * dx, ay + f * dy, ux, uy, way
            walked_m -= leg
        last = self._legs[-1]  # past the end by a rounding
        return last[0] + last[2], last[1] + last[3], last[5], last[6], way

    def position_at(self, t_s: float) -> tuple[float, float]:
        """Where the person is at ``t_s`` (s) if nothing stopped it on the way (m, world frame)."""
        return self.point_at(self.walked_by(t_s))


Obstacle = Union[BoxObstacle, CylinderObstacle, Person]
"""Any obstacle of a world."""

OTHERS_MAX_AGE_S: float = 1.0
"""Another robot's pose older than this (wall s) is dropped: a robot that went away is no longer an obstacle."""


@dataclass(frozen=True)
class OtherRobot:
    """Another robot in the same simulated world, as its own simulator last published it: an upright circle of
    ``radius_m`` (its footprint, m) at ``x``, ``y`` (m, world frame) facing ``yaw`` (rad).

    Its pose is set from outside (the fleet): it is neither a fixed obstacle nor a person that walks a path, and the
    simulator that sees it does not move it (its own simulator does).
    """

    name: str
    x: float
    y: float
    yaw: float
    radius_m: float


class OtherRobots:
    """The hand-over of other robots' poses from the thread that hears them to the simulator's loop.

    :meth:`put` (any thread: the fleet's) replaces what is known of the robots it names; :meth:`take` (the sim loop,
    between ticks) is a snapshot of those heard within :data:`OTHERS_MAX_AGE_S`, in name order, so that what the
    simulator does with it depends only on the poses handed over. ``wall`` is a monotonic clock (s).
    """

    def __init__(self, wall: Callable[[], float] = time.monotonic, max_age_s: float = OTHERS_MAX_AGE_S) -> None:
        self.wall = wall
        self.max_age_s = float(max_age_s)
        self._lock = threading.Lock()
        self._heard: dict[str, tuple[float, OtherRobot]] = {}

    def put(self, robots: Iterable[tuple[OtherRobot, float]]) -> None:
        """Each ``(robot, age_s)``: its pose, heard ``age_s`` ago (s, as the sender counts it)."""
        now = self.wall()
        with self._lock:
            for robot, age_s in robots:
                self._heard[robot.name] = (now - max(0.0, float(age_s)), robot)

    def take(self) -> tuple[OtherRobot, ...]:
        """The robots heard within the last :data:`OTHERS_MAX_AGE_S`, by name (older ones are forgotten)."""
        oldest = self.wall() - self.max_age_s
        with self._lock:
            for name in [n for n, (t, _) in self._heard.items() if t < oldest]:
                del self._heard[name]
            return tuple(r for _, (_, r) in sorted(self._heard.items()))


def _default(shape: str, name: str) -> Any:
    """The world schema's default for field ``name`` of a ``shape`` obstacle."""
    return schema_default(f"world.schema.json#/$defs/{shape}_obstacle", name)


def obstacle_of(d: dict) -> Obstacle:
    """The obstacle of one checked ``obstacles:`` item (numbers already in the field's units: m, m/s, s, deg)."""
    shape = d["shape"]
    if shape == "box":
        length, width = (float(v) for v in d["size_m"])
        return BoxObstacle(float(d["x"]), float(d["y"]), length, width, math.radians(float(d.get("yaw_deg", _default("box", "yaw_deg")))),
                           d.get("colour"))
    if shape == "cylinder":
        return CylinderObstacle(float(d["x"]), float(d["y"]), float(d["radius_m"]))
    if shape == "person":
        return Person(radius_m=float(d.get("radius_m", _default("person", "radius_m"))),
                      speed_mps=float(d.get("speed_mps", _default("person", "speed_mps"))),
                      path=tuple((float(p[0]), float(p[1])) for p in d["path"]),
                      start_s=float(d.get("start_s", _default("person", "start_s"))),
                      loop=bool(d.get("loop", _default("person", "loop"))),
                      keeps_m=float(d.get("keeps_m", _default("person", "keeps_m"))),
                      patience_s=float(d.get("patience_s", _default("person", "patience_s"))),
                      gives_way=bool(d.get("gives_way", _default("person", "gives_way"))))
    raise ValueError(f"unknown obstacle shape {shape!r}")


def obstacle_outline(o: Obstacle) -> dict:
    """What a map draws of an obstacle (m, world frame): a box's ``corners``, a cylinder's ``xy`` and ``radius_m``,
    a person's ``path`` and ``radius_m`` (where it walks; it is drawn at the path's start)."""
    if isinstance(o, BoxObstacle):
        return {"shape": "box", "corners": [[round(x, 3), round(y, 3)] for x, y in o.corners()]}
    if isinstance(o, CylinderObstacle):
        return {"shape": "cylinder", "xy": [o.x, o.y], "radius_m": o.radius_m}
    return {"shape": "person", "path": [list(p) for p in o.path], "radius_m": o.radius_m}


__all__ = ["BoxObstacle", "CylinderObstacle", "Person", "Obstacle", "OtherRobot", "OtherRobots", "OTHERS_MAX_AGE_S",
           "obstacle_of", "obstacle_outline", "CLOSED_PATH_TOLERANCE_M"]
