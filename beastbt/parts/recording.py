"""Recording as a part of every run: the MCAP recorder attached to the assembled run, and its summary line."""

from __future__ import annotations

from beastbt.recording.recorder import install
from beastbt.robot.part import Part
from beastbt.run.session import Prepared


class RecordingPart(Part):
    """Every run recorded (``<run folder>/run.mcap``, ``--record FILE``); nothing when the run does not record."""

    name = "recording"
    schema = "parts/recording.schema.json"
    reads = ("odometry", "imu", "gps_fix", "pose", "battery", "joystick")

    def install(self, prepared: Prepared) -> None:
        """Attach the recorder (it adds ``recording`` to the summary itself)."""
        install(prepared)


__all__ = ["RecordingPart"]
