"""The fleet as a part: ``--fleet ENDPOINT`` reports the run to a station on Zenoh and takes its commands.

:class:`FleetPart` is assembled only for a run with ``--fleet`` (or ``beastbt serve``); every other run gets
:class:`UnsupervisedCheck`, which reads nothing and imports no Zenoh: it refuses, before anything moves, a
mission (or profile) whose ``fleet:`` section requires the station's supervision (:mod:`beastbt.fleet.supervision`).
A replay is never on the fleet.
"""

from __future__ import annotations

from beastbt.robot.part import REPLAY, Build, Part, RefusalCheck
from beastbt.run.session import Prepared


class FleetPart(Part):
    """A robot on the fleet: its state, events, liveliness and command queryables (docs/fleet.md)."""

    name = "fleet"
    opens = "Zenoh session (peer, connecting to the station's router)"
    reads = ("battery",)
    """It shows what the run computes (the console's state) and the battery, and wakes no other sensor."""
    takes = ("pause, resume, abort, e-stop, answers, missions (serve)", "velocity (teleop source of the mux)")
    mode = ""

    def attach(self, build: Build) -> None:
        """Note the mode: a replay is never on the fleet (its commands are the recording's)."""
        self.mode = build.mode

    def install(self, prepared: Prepared) -> None:
        """Attach the run to the fleet's agent (the one ``beastbt serve`` keeps, or one for this run)."""
        fleet = prepared.options.fleet
        if self.mode == REPLAY or fleet is None:
            return
        from beastbt.fleet.run_link import FleetRunLink, open_agent
        from beastbt.fleet.supervision import supervise, supervision_of
        supervision = supervision_of(prepared.mission, prepared.profile)
        agent, owned = open_agent(fleet, prepared)
        link = FleetRunLink(agent, prepared)
        prepared.closers.append(link.close)
        prepared.after_summary.append(link.ended)  # the station hears of the end once the summary is on disk
        if owned:
            prepared.after_summary.append(lambda summary: agent.close())
            print(f"fleet: reporting as '{agent.name}' to {fleet.endpoint or fleet.config_file}", flush=True)
        if supervision is not None and supervision.required:
            supervise(prepared.run, supervision, lambda: agent.station_present)
        prepared.run.events.add("fleet", f"on the fleet as '{agent.name}' ({fleet.endpoint or fleet.config_file})")


class UnsupervisedCheck(RefusalCheck):
    """A run without a fleet link: refuses a mission or profile that requires the fleet's supervision."""

    name = "fleet_check"

    def check(self, prepared: Prepared) -> None:
        """InvalidInput, positioned at the ``fleet:`` section, when it requires supervision."""
        doc = prepared.mission.doc
        if (doc is None or "fleet" not in (doc.data or {})) and prepared.profile.section("fleet") is None:
            return  # the usual run: nothing to import
        from beastbt.fleet.supervision import refuse_unsupervised, supervision_of
        refuse_unsupervised(supervision_of(prepared.mission, prepared.profile))


__all__ = ["FleetPart", "UnsupervisedCheck"]
