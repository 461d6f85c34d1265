"""``fleet: {supervision: required, lost_after: 2 s, then: hold}``: a robot that goes on only while the station is seen.

The section may be in the mission (it wins) or in the robot profile (every
mission on that robot). With ``supervision: required`` a failsafe below the
tree (:meth:`~beastbt.run.failsafes.FailsafeMonitor.add`, the same watch and
actions as the mission's ``failsafes:``) triggers when the station's
liveliness token (``beastbt/fleet/station``) has not been seen for
``lost_after`` of the run's clock: ``hold`` stops the robot until the station
is back and then resumes the mission; ``stop`` ends it as failed. A run
without a fleet link cannot be supervised, so a mission that requires it is
refused before anything moves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Optional

from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.core.units import parse_quantity
from beastbt.mission.model import Failsafe
from beastbt.run.failsafes import absent_for

KIND = "fleet_lost"
"""The failsafe's kind, in events (``fleet_lost triggered: then hold``) and the run's ``paused_by``."""
DEFAULT_LOST_AFTER = "2 s"
DEFAULT_THEN = "hold"


@dataclass(frozen=True)
class Supervision:
    """The ``fleet:`` section in force: ``required``, ``lost_after_s`` (s), ``then`` (hold, stop), where it was
    written (``source``: ``mission`` or ``profile``) and a problem located there, for errors."""

    required: bool
    lost_after_s: float
    then: str
    source: str
    where: Callable[[str, str], Problem]


def supervision_of(mission: Any, profile: Any) -> Optional[Supervision]:
    """The ``fleet:`` section of the mission, else of the profile, parsed; None when neither has one."""
    for source, doc, section in (("mission", getattr(mission, "doc", None), _mission_section(mission)),
                                 ("profile", getattr(profile, "doc", None), profile.section("fleet"))):
        if not isinstance(section, dict):
            continue

        def where(message: str, hint: str, doc: Any = doc, source: str = source) -> Problem:
            if doc is not None:
                return doc.problem(("fleet",), message, hint, key=True)
            return Problem(source, Position(), message, hint)
        return Supervision(required=section.get("supervision", "none") == "required",
                           lost_after_s=parse_quantity(section.get("lost_after", DEFAULT_LOST_AFTER), "duration"),
                           then=str(section.get("then", DEFAULT_THEN)), source=source, where=where)
    return None


def _mission_section(mission: Any) -> Any:
    doc = getattr(mission, "doc", None)
    data = getattr(doc, "data", None)
    return data.get("fleet") if isinstance(data, dict) else None


def refuse_unsupervised(supervision: Optional[Supervision]) -> None:
    """InvalidInput when the section requires supervision and the run has no fleet link (nothing moved yet)."""
    if supervision is not None and supervision.required:
        raise InvalidInput([supervision.where(
            f"this {supervision.source} requires the fleet's supervision (fleet: supervision: required), and "
            f"the run has no fleet link", "run it with --fleet tls/STATION:7447 (or send it from a station to "
            "'beastbt serve'), or set supervision: none")])


def supervise(run: Any, supervision: Supervision, station_present: Callable[[], bool]) -> None:
    """Add the failsafe that acts when the station has not been seen for ``lost_after`` (see the module docstring)."""
    spec = Failsafe(KIND, supervision.then, {"after_s": supervision.lost_after_s}, ("fleet",))
    run.failsafes.add(spec, absent_for(station_present, supervision.lost_after_s))
    run.events.add("fleet", f"supervised by the station: if it is not seen for {supervision.lost_after_s:g} s, "
                            f"then {supervision.then}")


__all__ = ["Supervision", "supervision_of", "refuse_unsupervised", "supervise", "KIND"]
