"""One run reporting to the fleet: its state, events and controls, through the console's own parts.

The state is the operator console's (:class:`~beastbt.live.console_state.ConsoleState`,
built on the tick thread and handed over whole); the controls are the
console's (:class:`~beastbt.live.console_control.ConsoleControls`, carried
out on the tick thread, recorded for replay). With ``--console`` as well, the
console's own state and controls are shared rather than built twice; without
it, the link installs them as the console does (a tick hook and a reactor).
So there is one way to move the robot, whoever asks: the command mux under the e-stop latch.
"""

from __future__ import annotations

import time
from typing import Any, Optional

from beastbt.fleet.agent import FleetAgent
from beastbt.live.console_control import ConsoleControls
from beastbt.live.console_state import ConsoleState

STATE_PERIOD_S = 0.1
"""The fleet's state is built at most this often on the tick thread (wall s), as the console's."""


class FleetRunLink:
    """The run of ``prepared`` reporting through ``agent`` (see the module docstring)."""

    def __init__(self, agent: FleetAgent, prepared: Any) -> None:
        self.agent = agent
        self.run = prepared.run
        run = self.run
        console = run.ctx.services.plugins.get("console")
        wall = time.monotonic  # states and the stick's timeout are paced for people, in wall time
        self._state: Optional[ConsoleState] = None
        if console is not None:
            self.controls: ConsoleControls = console.controls
            state = console.state
            before = state.on_publish

            def both(seq: int, built: dict) -> None:
                if before is not None:
                    before(seq, built)
                self._latest = built
            state.on_publish = both
            self._latest: dict = state.latest().state
        else:
            self.controls = ConsoleControls(run, wall)
            state = self._state = ConsoleState(run, prepared.world, wall, STATE_PERIOD_S)
            self._latest = state.latest().state
            state.on_publish = self._take
            controls = self.controls
            pending = controls.pending

            def fleet_tick(run: Any, now_s: float) -> None:
                # most ticks have nothing queued: one cheap test, then the state (itself paced in wall time)
                if controls.stick_held or not pending.empty():
                    controls.apply_pending(now_s)
                state(run, now_s)

            run.hooks.insert(0, fleet_tick)  # before the tree, as the console's: a pause counts in the next tick
            run.reactors.append(controls)
        run.events.listeners.append(self._event)
        agent.attach(self)
        if run.io.sim is not None and prepared.options.world:
            # a world given on the command line is shared with the fleet's other simulated robots in it (each
            # mission's own world would put every robot on the same start)
            agent.attach_sim(run.io.sim)
        if agent.estop_latched:  # it came between the mission's answer and now: the run starts stopped
            from beastbt.run.safety import request_estop
            request_estop(run, "the fleet's e-stop (latched before the run)")

    def _take(self, seq: int, built: dict) -> None:
        self._latest = built

    def _event(self, event: Any) -> None:
        self.agent.publish_event(event.time_s, event.kind, event.text)
        if event.kind == "photo":  # the photo step has just noted it (beastbt.behaviours.photo.save_photo)
            watch = getattr(self.run.ctx.services, "vision", None)
            shot = watch.log.photos[-1] if watch is not None and watch.log.photos else None
            if shot is not None and shot.get("file"):
                self.agent.photo_taken(shot["name"], shot["time_s"], shot["file"])

    def latest(self) -> dict:
        """The run's last state (the console's fields)."""
        return self._latest

    def close(self) -> None:
        """The run has ended (a closer): hand over its final state and refuse further controls."""
        if self._state is not None:
            self._state.publish()
            self.controls.close()

    def ended(self, summary: Optional[dict]) -> None:
        """The run's summary is written (None: the run was abandoned): detach from the agent, which tells the
        station the robot is idle with this run's end (a station's reader then finds the run's summary)."""
        run = self.run
        self.agent.detach({"mission": run.mission.name, "status": run.status})





def robot_name(fleet: Any, profile: Any) -> str:
    """The robot's name on the fleet: ``--name``, else the profile's ``robot:`` name; InvalidInput if it is none."""
    from beastbt.core.errors import InvalidInput, Position, Problem
    from beastbt.fleet import keys
    name = fleet.name or str(profile.name)
    problem = keys.name_problem(name)
    if problem is not None:
        where = "--name" if fleet.name else str(profile.file or profile.name)
        raise InvalidInput([Problem(where, Position(), problem, "give the robot a name on the fleet with --name")])
    return name


def open_agent(fleet: Any, prepared: Any) -> tuple[FleetAgent, bool]:
    """The agent the run reports through: ``beastbt serve``'s own (not owned), or a new one for this run (owned)."""
    if fleet.agent is not None:
        return fleet.agent, False
    agent = FleetAgent(robot_name(fleet, prepared.profile), fleet)
    agent.start()
    return agent, True
__all__ = ["FleetRunLink", "open_agent", "robot_name"]
