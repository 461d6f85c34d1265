"""Recording as a part of every run: the MCAP recorder attached to the assembled run, and its summary line."""

from __future__ import annotations

from typing import Any, Optional

from beastbt.live.endpoint import parse_endpoint
from beastbt.recording.recorder import install
from beastbt.robot.part import Part
from beastbt.run.session import Prepared


def foxglove_endpoint(value: Any) -> Optional[tuple[str, int]]:
    """``RunOptions.foxglove`` (``[HOST:]PORT`` text or a (host, port) pair) as (host, port), or None."""
    if value is None:
        return None
    if isinstance(value, str):
        return parse_endpoint(value, "--foxglove")
    host, port = value
    return str(host), int(port)


class RecordingPart(Part):
    """Every run recorded (``<run folder>/run.mcap``, ``--record FILE``) and/or served to Foxglove live
    (``--foxglove [HOST:]PORT``); nothing when the run does neither. It reads nothing itself: the recording
    holds what the run used, and only ``--record-sensors`` wakes the parts that would sleep."""

    name = "recording"
    schema = "parts/recording.schema.json"
    # Nothing: a recording holds what the run used, and wakes no part the run lets sleep (the GPS, the IMU and
    # the EKF of a patrol). ``--record-sensors`` (RunOptions.record_sensors) keeps every part awake instead.
    reads = ()

    def install(self, prepared: Prepared) -> None:
        """Attach the recorder (it adds ``recording`` to the summary itself), with the live server if asked."""
        install(prepared, live=foxglove_endpoint(prepared.options.foxglove))


__all__ = ["RecordingPart"]
