"""How a run is recorded: :class:`RecordingConfig`, every knob with its unit and default.

Set through ``RunOptions.recording`` (a mapping) and ``beastbt run
--record-images HZ``; described for users in
``schemas/parts/recording.schema.json``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from beastbt.core.schema_defaults import schema_defaults
from beastbt.core.config import dataclass_from_dict


@dataclass
@schema_defaults("parts/recording.schema.json")
class RecordingConfig:
    """How a run is recorded (``RunOptions.recording``; ``--record-images HZ`` sets image_rate_hz)."""

    # Camera frames stored as JPEG on /camera/image, frames per clock second (Hz). 0 turns images off;
    # every frame still gets a small /sensors/camera message. Raise it to see more, lower it for smaller files.
    image_rate_hz: float
    # JPEG quality of recorded images, 1-100 (OpenCV's IMWRITE_JPEG_QUALITY).
    image_jpeg_quality: int
    # Images wider than this are scaled down before encoding (pixels); 0 keeps the camera's size.
    image_max_width_px: int
    # The poses and what is drawn from them (/odom, /estimate/*, /pose/fused, /gps/fused, /tf) and the
    # simulator's /truth are recorded at most this often (Hz); commands, events and the readings the run used
    # go every tick (replay needs them). 0 records the poses every tick too.
    pose_rate_hz: float
    # A run on a robot with a GPS records where it was even when nothing in it reads the position: the GPS stays
    # awake for the recording, and when the EKF sleeps it steps at each GPS fix and at least this often (Hz) for
    # the recording's position track (beastbt.recording.track), the wheels carrying the pose on between. 0: no fused track (the fixes still are).
    track_rate_hz: float
    # While the poses, the true pose and the gimbal stay the same (the robot stands still), they are recorded
    # only this often (s). 0 records them at pose_rate_hz all the same.
    still_interval_s: float
    # Ticks, events and servo commands waiting for the writer process (items), beyond what the pipe to it
    # holds (up to 1 MiB, ~1000 ticks). ~200 s at 20 Hz; on the robot an overflow drops items (counted in
    # the summary), in the simulator the loop waits instead.
    queue_max_items: int
    # What a full queue does: "auto" (wait on a simulated clock, drop on the robot), "block" or "drop".
    overflow: str
    # The tick loop hands its items to the writer process in batches, one pipe write per batch, at least
    # every this many clock seconds (s); events go at once. A run whose process dies loses at most this much.
    send_interval_s: float
    # A chunk is closed and handed to the OS every this many clock seconds of records (s). A run killed
    # hard loses at most this much; shorter chunks compress less well.
    chunk_interval_s: float
    # A chunk is also closed when its uncompressed size passes this (bytes), e.g. with many images.
    chunk_max_bytes: int
    # Chunk compression: "auto" (zstd if installed, else lz4, else none), "zstd", "lz4" or "none".
    compression: str
    # How long the end of a run waits for the writer to drain its queue before giving up (wall seconds).
    drain_timeout_s: float
    # Less free space than this where the recording goes, at the start of a run, is warned about (megabytes,
    # 10^6 bytes); 0 never warns. Should the disk fill, the recording stops (with an event), the mission goes on.
    min_free_mb: float
    # The recording stops cleanly (an event; the mission goes on) rather than leave less free space than this
    # on its disk (megabytes, 10^6 bytes); 0: only a full disk stops it. A run folder's recording takes the
    # profile's runs: min_free_mb.
    floor_free_mb: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.image_rate_hz) and self.image_rate_hz >= 0):
            raise ValueError(f"image_rate_hz must be zero or positive, got {self.image_rate_hz}")
        if not 1 <= self.image_jpeg_quality <= 100:
            raise ValueError(f"image_jpeg_quality must be 1-100, got {self.image_jpeg_quality}")
        if self.image_max_width_px < 0:
            raise ValueError(f"image_max_width_px must be zero or positive, got {self.image_max_width_px}")
        if not (math.isfinite(self.pose_rate_hz) and self.pose_rate_hz >= 0):
            raise ValueError(f"pose_rate_hz must be zero or positive, got {self.pose_rate_hz}")
        if not (math.isfinite(self.track_rate_hz) and self.track_rate_hz >= 0):
            raise ValueError(f"track_rate_hz must be zero or positive, got {self.track_rate_hz}")
        if not (math.isfinite(self.still_interval_s) and self.still_interval_s >= 0):
            raise ValueError(f"still_interval_s must be zero or positive, got {self.still_interval_s}")
        if self.queue_max_items < 1:
            raise ValueError(f"queue_max_items must be at least 1, got {self.queue_max_items}")
        if self.overflow not in ("auto", "block", "drop"):
            raise ValueError(f"overflow must be auto, block or drop, not '{self.overflow}'")
        if not (math.isfinite(self.send_interval_s) and self.send_interval_s >= 0):
            raise ValueError(f"send_interval_s must be zero or positive, got {self.send_interval_s}")
        if not (math.isfinite(self.chunk_interval_s) and self.chunk_interval_s > 0):
            raise ValueError(f"chunk_interval_s must be positive, got {self.chunk_interval_s}")
        if self.chunk_max_bytes < 1024:
            raise ValueError(f"chunk_max_bytes must be at least 1024, got {self.chunk_max_bytes}")
        if self.compression not in ("auto", "zstd", "lz4", "none"):
            raise ValueError(f"compression must be auto, zstd, lz4 or none, not '{self.compression}'")
        if not (math.isfinite(self.min_free_mb) and self.min_free_mb >= 0):
            raise ValueError(f"min_free_mb must be zero or positive, got {self.min_free_mb}")
        if not self.drain_timeout_s > 0:
            raise ValueError(f"drain_timeout_s must be positive, got {self.drain_timeout_s}")

    @classmethod
    def from_dict(cls, d: Any) -> "RecordingConfig":
        """Build from a dict; an unknown key or a bad value raises ``ValueError``."""
        return dataclass_from_dict(cls, d, "recording")


@dataclass
@schema_defaults("parts/frames.schema.json")
class FramesConfig:
    """Names of the coordinate frames (robot profile ``frames:``), REP-105: map -> odom -> base_link -> camera."""

    # The world-fixed frame: the estimator's local east-north-up frame (metres) at the datum.
    map: str
    # Continuous dead-reckoning frame; map -> odom is the correction the GPS makes.
    odom: str
    # The robot body: x forward, y left, z up, origin at the robot centre on the floor.
    base_link: str
    # The camera on its gimbal: x along the optical axis, y left, z up.
    camera_link: str
    # The camera's optical frame (z forward, x right, y down): images and their calibration are in it.
    camera_optical: str
    # The frame of GPS fixes.
    gps: str

    def __post_init__(self) -> None:
        names = [self.map, self.odom, self.base_link, self.camera_link, self.camera_optical]
        if len(set(names)) != len(names):
            raise ValueError(f"frames: map, odom, base_link, camera_link and camera_optical must differ, got {names}")

    @classmethod
    def from_dict(cls, d: Any) -> "FramesConfig":
        """Build from a profile's ``frames:`` mapping (None: all defaults); bad keys raise ``ValueError``."""
        return dataclass_from_dict(cls, d or {}, "frames")


def compression_type(name: str) -> Any:
    """The ``mcap`` CompressionType for ``name`` (``auto`` picks zstd, then lz4, then none by what is installed)."""
    from mcap import writer as mw
    if name == "auto":
        name = "zstd" if mw.zstandard is not None else ("lz4" if mw.lz4 is not None else "none")
    return {"zstd": mw.CompressionType.ZSTD, "lz4": mw.CompressionType.LZ4,
            "none": mw.CompressionType.NONE}[name]


# -- conversions (writer thread) ----------------------------------------------------------


__all__ = ["RecordingConfig", "FramesConfig", "compression_type"]
