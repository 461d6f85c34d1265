"""Conditions of the mission language, evaluated against the blackboard.

A :class:`Condition` answers ``holds()`` now; it is used by ``if``, ``while``,
``wait_until`` and failsafes, and as a leaf by :class:`CheckCondition`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import py_trees

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard import catalogue
from beastbt.estimation.geodesy import distance_m

CONDITION_KEYS = ("now_s", "mission_start_s", "line", "gps_fix", "teleop_active", "battery", "pose", "pose_odom")


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


@dataclass
class Condition:
    """A named test of the robot's situation: ``text`` for people, ``test`` for the tree."""

    text: str
    test: Callable[[ConditionReader], bool]
    reader: ConditionReader

    def holds(self) -> bool:
        """True when the condition holds now."""
        return bool(self.test(self.reader))

    def __str__(self) -> str:
        return self.text


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


class CheckCondition(BeastBehaviour):
    """A leaf that succeeds when its condition holds and fails otherwise (never RUNNING)."""

    def __init__(self, name: str, ctx: MissionContext, condition: Condition) -> None:
        super().__init__(name, ctx)
        self.condition = condition

    def update(self) -> Status:
        return Status.SUCCESS if self.condition.holds() else Status.FAILURE
