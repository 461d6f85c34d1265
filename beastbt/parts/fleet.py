"""The fleet as a part: ``--fleet ENDPOINT`` reports the run to a station on Zenoh and takes its commands.

Costs nothing (and imports no Zenoh) for a run without ``--fleet`` whose mission and profile have no
``fleet:`` section; a mission that requires the fleet's supervision without a fleet link is refused
before anything moves (:mod:`beastbt.fleet.supervision`).
"""

from __future__ import annotations

from beastbt.robot.part import REPLAY, Build, Part
from beastbt.run.session import Prepared


class FleetPart(Part):
    """A robot on the fleet: its state, events, liveliness and command queryables (docs/fleet.md)."""

    name = "fleet"
    opens = "Zenoh session (peer, connecting to the station's router)"
    reads = ("battery",)
    """It shows what the run computes (the console's state) and wakes no sleeping sensor."""
    takes = ("pause, resume, abort, e-stop, answers, missions (serve)", "velocity (teleop source of the mux)")

    mode = ""

    def attach(self, build: Build) -> None:
        """Note the mode: a replay is never on the fleet (its commands are the recording's)."""
        self.mode = build.mode

    def install(self, prepared: Prepared) -> None:
        """Attach the run to the fleet's agent (the one ``beastbt serve`` keeps, or one for this run)."""
        if self.mode == REPLAY:
            return
        fleet = getattr(prepared.options, "fleet", None)
        section = (prepared.mission.doc.data or {}).get("fleet") if prepared.mission.doc is not None else None
        if fleet is None and section is None and prepared.profile.section("fleet") is None:
            return
        from beastbt.fleet.supervision import refuse_unsupervised, supervise, supervision_of
        supervision = supervision_of(prepared.mission, prepared.profile)
        if fleet is None:
            refuse_unsupervised(supervision)
            return
        from beastbt.fleet.run_link import FleetRunLink, open_agent
        agent, owned = open_agent(fleet, prepared)
        link = FleetRunLink(agent, prepared)
        prepared.closers.append(link.close)
        if owned:
            prepared.closers.append(agent.close)
        if supervision is not None and supervision.required:
            supervise(prepared.run, supervision, lambda: agent.station_present)
        prepared.run.events.add("fleet", f"on the fleet as '{agent.name}' ({fleet.endpoint or fleet.config_file})")


__all__ = ["FleetPart"]
