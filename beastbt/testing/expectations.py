"""A mission test's expectations checked against one run's summary, each failure said in the summary's words.

Every expectation reads the summary (``schemas/summary.schema.json``) and
nothing else, so what a test checks is what anyone can read after any run:
``status``, the reached ``waypoints``, ``truth.collisions``,
``truth.min_clearance_m``, ``sim_time_s``, ``truth.fences_entered``, the
``ask`` events and the ``events``. A failure names the expectation, what it
wanted and the value the run had (the seed is the caller's to add).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

from beastbt.testing.spec import Bound, Expectations


@dataclass(frozen=True)
class Failure:
    """One expectation that did not hold: its ``name`` (``status``, ``reached``...), what was ``wanted`` and what
    was ``seen``, in words."""

    name: str
    wanted: str
    seen: str

    def words(self) -> str:
        """``expect.status: wanted success, saw failure``."""
        return f"expect.{self.name}: wanted {self.wanted}, saw {self.seen}"


def reached_places(summary: dict) -> list[str]:
    """The places reached in the run, in order (GPS ``waypoints`` and map ``map_waypoints``, by time)."""
    visits = [w for w in (summary.get("waypoints") or []) + (summary.get("map_waypoints") or []) if w.get("reached")]
    visits.sort(key=lambda w: w.get("time_s") if w.get("time_s") is not None else float("inf"))
    return [str(w["name"]) for w in visits]


def asked_questions(summary: dict) -> list[str]:
    """The ids of the questions the mission asked (its ``ask`` events ``ID: text (yes / no)``), in order, once each."""
    ids: list[str] = []
    for e in summary.get("events") or []:
        if e.get("kind") == "ask" and ": " in e.get("text", "") and not e["text"].startswith("nobody can answer"):
            qid = e["text"].split(": ", 1)[0]
            if qid not in ids:
                ids.append(qid)
    return ids


def _in_order(wanted: list[str], seen: list[str]) -> bool:
    it = iter(seen)
    return all(any(name == s for s in it) for name in wanted)


def _number(seen: Optional[float], unit: str) -> str:
    return "nothing (not measured in this run)" if seen is None else f"{seen:g}{unit}"


def _bound(name: str, bound: Optional[Bound], seen: Optional[float], unit: str) -> Optional[Failure]:
    if bound is None:
        return None
    if seen is None or not bound.holds(float(seen)):
        return Failure(name, f"'{bound.text}'", _number(seen, unit))
    return None


def check(expect: Expectations, summary: dict) -> list[Failure]:
    """Every expectation of ``expect`` that ``summary`` does not meet, in the order of the schema."""
    out: list[Failure] = []
    truth: dict[str, Any] = summary.get("truth") or {}
    if expect.status is not None and summary.get("status") != expect.status:
        end = next((e["text"] for e in reversed(summary.get("events") or []) if e.get("kind") == "mission_end"), None)
        out.append(Failure("status", expect.status, f"{summary.get('status')}" + (f" ({end})" if end else "")))
    if expect.reached:
        reached = reached_places(summary)
        if not _in_order(expect.reached, reached):
            out.append(Failure("reached", f"{expect.reached} in this order",
                               f"{reached} reached" if reached else "no place reached"))
    for failure in (_bound("collisions", expect.collisions, truth.get("collisions"), ""),
                    _bound("min_clearance", expect.min_clearance, truth.get("min_clearance_m"), " m"),
                    _bound("time", expect.time, summary.get("sim_time_s"), " s")):
        if failure is not None:
            out.append(failure)
    if expect.never_in:
        entered = [f for f in truth.get("fences_entered") or [] if f in expect.never_in]
        if entered:
            out.append(Failure("never_in", f"never in {expect.never_in}", f"entered {entered}"))
    if expect.asked:
        asked = asked_questions(summary)
        missing = [q for q in expect.asked if q not in asked]
        if missing:
            out.append(Failure("asked", f"{expect.asked} asked", f"{asked} asked" if asked else "no question asked"))
    for i, want in enumerate(expect.events):
        kind, text = str(want.get("kind")), str(want.get("text", ""))
        if not any(e.get("kind") == kind and text in e.get("text", "") for e in summary.get("events") or []):
            of_kind = [e["text"] for e in summary.get("events") or [] if e.get("kind") == kind]
            seen = (f"{len(of_kind)} {kind} event(s): " + "; ".join(of_kind[:3]) + (" ..." if len(of_kind) > 3 else "")
                    if of_kind else f"no {kind} event")
            out.append(Failure(f"events[{i}]", f"a {kind} event with '{text}'" if text else f"a {kind} event", seen))
    return out


__all__ = ["Failure", "check", "reached_places", "asked_questions"]
