"""Recording as a part of every run: the MCAP recorder attached to the assembled run, and its summary line."""

from __future__ import annotations

from typing import Any, Optional

from beastbt.live.endpoint import parse_endpoint
from beastbt.recording.recorder import install
from beastbt.recording.track import install_track
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
    (``--foxglove [HOST:]PORT``); nothing when the run does neither. It reads the GPS fix only: the recording
    holds what the run used and where the robot was (:mod:`beastbt.recording.track`), and only
    ``--record-sensors`` wakes the other parts that would sleep."""

    name = "recording"
    schema = "parts/recording.schema.json"
    # The GPS fix: every recording keeps where the robot was (the fixes, and the fused pose of the position track
    # when the EKF sleeps), so that any run with a GPS can be taught (``beastbt route from-run``). It wakes no other
    # part the run lets sleep (the IMU of a patrol); ``--record-sensors`` (RunOptions.record_sensors) keeps every
    # part awake instead.
    reads = ("gps_fix",)

    def install(self, prepared: Prepared) -> None:
        """Attach the recorder (it adds ``recording`` to the summary itself), with the live server if asked."""
        rec = install(prepared, live=foxglove_endpoint(prepared.options.foxglove))
        if rec is not None:
            from beastbt.parts.navigation import ekf_estimator
            profile, run = prepared.profile, prepared.run
            install_track(prepared, rec.config.track_rate_hz, lambda: ekf_estimator(profile, run.io, prepared.events))


__all__ = ["RecordingPart"]
