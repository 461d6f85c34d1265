"""Conditions of the mission language, evaluated against the blackboard.

A :class:`Condition` answers ``holds()`` now; it is used by ``if``, ``while``,
``wait_until`` and failsafes, and as a leaf by :class:`CheckCondition`.

A test returns True, False, or None for *unknown* (``obstacle_within``
without a fresh scan): unknown never holds, ``not`` of unknown stays unknown,
and ``all``/``any`` combine them as Kleene's three-valued logic does
(:func:`not_of`, :func:`all_of`, :func:`any_of`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import py_trees

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard import catalogue
from beastbt.estimation.geodesy import distance_m

CONDITION_KEYS = ("now_s", "mission_start_s", "line", "gps_fix", "teleop_active", "battery", "pose", "pose_odom",
                  "scan", "map_pose")


class ConditionReader:
    """One read-only blackboard client shared by the conditions of a mission."""

    def __init__(self, ctx: MissionContext) -> None:
        self.ctx = ctx
        self.client = py_trees.blackboard.Client(name="conditions")
        for key in CONDITION_KEYS:
            catalogue.register(self.client, key)

    def get(self, key: str) -> object:
        """The value of ``key`` or None."""
        return catalogue.get(self.client, key)

    def fresh(self, key: str, max_age_s: Optional[float] = None) -> object:
        """The value of ``key`` when measured within ``max_age_s`` (default: the sensor max age), else None."""
        value = self.get(key)
        age = self.ctx.params.sensor_max_age_s if max_age_s is None else max_age_s
        return value if catalogue.is_fresh(value, self.ctx.now(), age) else None


Test = Callable[[ConditionReader], Optional[bool]]
"""A condition's test: True (holds), False (does not), None (unknown: what it reads is missing or too old)."""


@dataclass
class Condition:
    """A named test of the robot's situation: ``text`` for people, ``test`` for the tree.

    ``detail()``, when given, says what made it hold at the last test (``' (nearest 0.42 m at 12 deg)'``).
    """

    text: str
    test: Test
    reader: ConditionReader
    detail: Optional[Callable[[], str]] = None

    def holds(self) -> bool:
        """True when the condition holds now (unknown does not hold)."""
        answer = self.test(self.reader)
        return answer is not None and bool(answer)  # bool(): a numpy bool from a reading counts as well

    def details(self) -> str:
        """What made it hold at the last test, or ''."""
        return self.detail() if self.detail is not None else ""

    def __str__(self) -> str:
        return self.text


def not_of(inner: Test) -> Test:
    """``not``: the opposite of a known answer; unknown stays unknown."""
    def test(r: ConditionReader) -> Optional[bool]:
        answer = inner(r)
        return None if answer is None else not answer
    return test


def _decided_by(parts: list[Test], decisive: bool) -> Test:
    """Three-valued ``all``/``any``: ``decisive`` as soon as one part answers it, else unknown when one is
    unknown, else the other answer."""
    def test(r: ConditionReader) -> Optional[bool]:
        unknown = False
        for part in parts:
            answer = part(r)
            if answer is None:
                unknown = True
            elif bool(answer) is decisive:
                return decisive
        return None if unknown else not decisive
    return test


def all_of(parts: list[Test]) -> Test:
    """``all``: False when one is False, else unknown when one is unknown, else True."""
    return _decided_by(parts, False)


def any_of(parts: list[Test]) -> Test:
    """``any``: True when one is True, else unknown when one is unknown, else False."""
    return _decided_by(parts, True)


GPS_MAX_AGE_S = 2.0
"""A fix older than this no longer counts for gps_fix (s); the MTK3339 sends at 1 Hz by default."""


def line_flag(attr: str) -> Callable[[ConditionReader], bool]:
    """A test that a fresh line observation has ``attr`` set."""
    def test(r: ConditionReader) -> bool:
        obs = r.fresh("line")
        return bool(obs is not None and getattr(obs, attr))
    return test


def gps_fix(r: ConditionReader) -> bool:
    """A fresh GPS fix exists."""
    return r.fresh("gps_fix", GPS_MAX_AGE_S) is not None


def teleop_active(r: ConditionReader) -> bool:
    """The operator holds the enable button."""
    return bool(r.get("teleop_active"))


def battery_below(volts: float) -> Callable[[ConditionReader], bool]:
    """A test that the latest battery voltage is below ``volts``."""
    def test(r: ConditionReader) -> bool:
        b = r.fresh("battery", 5.0)
        return b is not None and b.voltage_v < volts
    return test


def elapsed(seconds: float) -> Callable[[ConditionReader], bool]:
    """A test that at least ``seconds`` passed since the mission started."""
    def test(r: ConditionReader) -> bool:
        start = r.get("mission_start_s")
        return start is not None and r.ctx.now() - start >= seconds
    return test


def near(lat: Optional[float], lon: Optional[float], within_m: float, place: str) -> Callable[[ConditionReader], bool]:
    """A test that the fused position is within ``within_m`` of a place (``home`` resolves at run time)."""
    def test(r: ConditionReader) -> bool:
        pose = r.get("pose")
        if pose is None or not pose.position_valid or pose.lat is None:
            return False
        target = (lat, lon)
        if lat is None:
            target = r.ctx.services.home()
            if target is None:
                return False
        return distance_m(pose.lat, pose.lon, target[0], target[1]) <= within_m
    return test


def sector_width_rad(start_rad: float, end_rad: float) -> float:
    """How far a sector reaches counterclockwise from ``start_rad`` to ``end_rad``, in (0, 2 pi] rad.

    Ends a whole number of turns apart but written differently (``[-180, 180]``)
    make the full circle; ends written the same are refused by the mission's checks.
    """
    width = math.fmod(end_rad - start_rad, 2.0 * math.pi)
    if width <= 1e-12:
        width += 2.0 * math.pi
    return width


class CheckCondition(BeastBehaviour):
    """A leaf that succeeds when its condition holds and fails otherwise (never RUNNING)."""

    def __init__(self, name: str, ctx: MissionContext, condition: Condition) -> None:
        super().__init__(name, ctx)
        self.condition = condition

    def update(self) -> Status:
        return Status.SUCCESS if self.condition.holds() else Status.FAILURE
