"""Talking to the operator: messages and camera snapshots."""

from __future__ import annotations

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext


class Say(BeastBehaviour):
    """Write ``text`` to the operator (console and the run's events). Succeeds at once; never fails."""

    def __init__(self, name: str, ctx: MissionContext, text: str) -> None:
        super().__init__(name, ctx)
        self.text = text

    def update(self) -> Status:
        self.ctx.events.add("say", self.text)
        return Status.SUCCESS


class Snapshot(BeastBehaviour):
    """Save the newest camera frame as ``<name>.jpg`` in the run's folder.

    Succeeds when saved (or, after noting it, when the run is not recorded or
    the file cannot be written: a full disk does not stop the mission); fails
    when there is no fresh camera frame.
    """

    READS = ("camera_frame",)

    def __init__(self, name: str, ctx: MissionContext, label: str) -> None:
        super().__init__(name, ctx)
        self.label = label

    def update(self) -> Status:
        frame = self.read("camera_frame")
        if frame is None or self.now() - frame.stamp_s > self.ctx.params.sensor_max_age_s:
            return self.fail("no camera frame")
        save = self.ctx.services.save_snapshot
        if save is None:
            self.ctx.events.add("snapshot", f"{self.label}: not saved (the run is not recorded)")
            return Status.SUCCESS
        try:
            path = save(self.label, frame)
        except OSError as exc:
            self.ctx.events.add("snapshot", f"{self.label}: not saved ({exc.strerror or exc})")
            return Status.SUCCESS
        self.ctx.events.add("snapshot", f"{self.label}: saved {path}")
        return Status.SUCCESS


class NotAvailable(BeastBehaviour):
    """A step this robot (or this version) cannot do. Fails at once, saying why."""

    def __init__(self, name: str, ctx: MissionContext, reason: str) -> None:
        super().__init__(name, ctx)
        self.reason = reason

    def update(self) -> Status:
        return self.fail(f"not available on this robot: {self.reason}")
