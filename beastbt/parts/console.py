"""The operator console as a part: ``--console [HOST:]PORT`` serves the live page, API and video for the run."""

from __future__ import annotations

from beastbt.robot.part import Part
from beastbt.run.session import Prepared


class ConsolePart(Part):
    """The operator console; costs nothing (and imports nothing) when ``--console`` is not given."""

    name = "console"
    opens = "TCP port (HTTP, WebSocket)"
    reads = ("battery",)
    """It shows what the run computes and wakes no sleeping sensor: watching must not change the run's cost
    (a mission that never reads GPS shows no GPS fix, and the pose from odometry)."""
    takes = ("pause, resume, abort, e-stop, answers", "velocity (teleop source of the mux, as a joystick)")

    def install(self, prepared: Prepared) -> None:
        """Start the console's server when the run asks for one."""
        if prepared.options.console is None:
            return
        from beastbt.live.console import install_console  # imports aiohttp and OpenCV: only with a console
        install_console(prepared)


__all__ = ["ConsolePart"]
