"""Failsafes: conditions watched on every tick, above the mission and before it.

Each :class:`FailsafeWatch` turns a mission ``failsafes:`` entry into a test
and a state (armed, triggered). The runner acts on what :meth:`FailsafeMonitor.check`
returns: ``stop`` ends the mission as failed, ``hold`` stops the robot until
the condition clears and then resumes, ``return_home`` and ``teleop`` hand over.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

from beastbt.blackboard.types import BatteryState, FusedPose, GpsFix, MapPose
from beastbt.estimation.geodesy import distance_m
from beastbt.mission.model import HOME, Failsafe, Mission


@dataclass
class Situation:
    """What the failsafes look at on one tick."""

    now_s: float
    mission_start_s: float
    gps_fix: Optional[GpsFix]
    battery: Optional[BatteryState]
    pose: Optional[FusedPose]
    home: Optional[tuple[float, float]]
    map_pose: Optional[MapPose] = None
    """The pose on the mission's map (None without ``map:``)."""


@dataclass
class FailsafeWatch:
    """One failsafe: its spec, a test of the situation, and whether it is triggered now."""

    spec: Failsafe
    test: Callable[[Situation], bool]
    triggered: bool = False
    since_s: Optional[float] = None


FAILSAFE_READS: dict[str, tuple[str, ...]] = {
    "gps_lost": ("gps_fix",), "battery_low": ("battery",), "geofence": ("pose", "home"), "keepout": ("pose",),
    "localization_lost": ("map_pose",)}
"""Blackboard keys (and readings) each failsafe watches."""
ACTION_READS: dict[str, tuple[str, ...]] = {"return_home": ("pose", "home")}
"""What a ``then:`` or ``on_failure:`` action needs kept up to date."""


def failsafe_reads(mission: Mission) -> frozenset[str]:
    """What the mission's failsafes and its ``on_failure`` action read."""
    keys: set[str] = set(ACTION_READS.get(mission.on_failure, ()))
    for f in mission.failsafes:
        keys.update(FAILSAFE_READS.get(f.kind, ("pose", "gps_fix", "battery", "home")))
        keys.update(ACTION_READS.get(f.then, ()))
    return frozenset(keys)


def absent_for(present: Callable[[], bool], after_s: float) -> Callable[[Situation], bool]:
    """A failsafe's test: ``present()`` has been False for ``after_s`` (s of the run's clock) or more.

    ``present`` is read once a tick (a link's state, written by its I/O thread);
    the time it has been absent is counted on the run's clock, from the first
    tick it was seen absent (from the start when it never was present).
    """
    state: dict = {"absent_since": None}

    def absent(s: Situation) -> bool:
        if present():
            state["absent_since"] = None
            return False
        if state["absent_since"] is None:
            state["absent_since"] = s.now_s
        return s.now_s - state["absent_since"] >= after_s
    return absent


class FailsafeMonitor:
    """Evaluates the mission's failsafes every tick."""

    def __init__(self, mission: Mission) -> None:
        self.watches = [FailsafeWatch(f, self._test_for(f, mission)) for f in mission.failsafes]

    @staticmethod
    def _test_for(f: Failsafe, mission: Mission) -> Callable[[Situation], bool]:
        p = f.params
        if f.kind == "gps_lost":
            def gps_lost(s: Situation) -> bool:
                last = s.gps_fix.stamp_s if s.gps_fix is not None else s.mission_start_s
                return s.now_s - last > p["after_s"]
            return gps_lost
        if f.kind == "battery_low":
            state = {"below_since": None}

            def battery_low(s: Situation) -> bool:
                if s.battery is None or s.battery.voltage_v >= p["below_v"]:
                    state["below_since"] = None
                    return False
                if state["below_since"] is None:
                    state["below_since"] = s.now_s
                return s.now_s - state["below_since"] >= p["for_s"]
            return battery_low
        if f.kind == "localization_lost":
            lost = {"since": None}

            def localization_lost(s: Situation) -> bool:
                # Without a map pose yet there is nothing to judge; only a localiser saying "lost" counts.
                if s.map_pose is None or s.map_pose.localized:
                    lost["since"] = None
                    return False
                if lost["since"] is None:
                    lost["since"] = s.now_s
                return s.now_s - lost["since"] >= p["after_s"]
            return localization_lost
        if "fence" in p:
            fence, margin = mission.fences[p["fence"]], p["margin_m"]

            def crossed(s: Situation) -> bool:
                if s.pose is None or not s.pose.position_valid or s.pose.lat is None:
                    return False
                return fence.crossed(s.pose.lat, s.pose.lon, margin)
            return crossed
        center = p["center"]

        def geofence(s: Situation) -> bool:
            if s.pose is None or not s.pose.position_valid or s.pose.lat is None:
                return False
            if center == HOME:
                if s.home is None:
                    return False
                lat, lon = s.home
            else:
                place = mission.places[center]
                lat, lon = place.lat, place.lon
            return distance_m(lat, lon, s.pose.lat, s.pose.lon) > p["radius_m"]
        return geofence

    def add(self, spec: Failsafe, test: Callable[[Situation], bool]) -> FailsafeWatch:
        """Watch one more failsafe that is not in the mission's ``failsafes:`` (a part's, such as the fleet's
        supervision); it acts as those do (``hold``, ``stop``)."""
        watch = FailsafeWatch(spec, test)
        self.watches.append(watch)
        return watch

    def check(self, s: Situation) -> list[tuple[FailsafeWatch, str]]:
        """Update every watch; return (watch, "trigger"|"clear") for those that changed this tick."""
        changes = []
        for w in self.watches:
            now = w.test(s)
            if now and not w.triggered:
                w.triggered, w.since_s = True, s.now_s
                changes.append((w, "trigger"))
            elif not now and w.triggered:
                w.triggered, w.since_s = False, None
                changes.append((w, "clear"))
        return changes

    def holding(self) -> bool:
        """True while any 'hold' failsafe is triggered."""
        return any(w.triggered and w.spec.then == "hold" for w in self.watches)
