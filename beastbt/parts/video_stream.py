"""Live video as a part: ``--stream [HOST:]PORT`` serves the camera (with the overlay) as MJPEG over HTTP."""

from __future__ import annotations

from beastbt.robot.part import Part
from beastbt.run.session import Prepared


class VideoStreamPart(Part):
    """The live MJPEG stream; costs nothing (and imports nothing) when ``--stream`` is not given."""

    name = "video_stream"
    schema = "parts/video_stream.schema.json"
    opens = "TCP port (HTTP, MJPEG)"
    reads = ("camera_frame", "line")

    def install(self, prepared: Prepared) -> None:
        """Start the stream server when the run asks for one."""
        if prepared.options.stream is None:
            return
        from beastbt.live.video_stream import install_stream  # imports OpenCV: only when streaming
        install_stream(prepared)


__all__ = ["VideoStreamPart"]
