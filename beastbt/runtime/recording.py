"""Every run recorded: an MCAP file (``run.mcap``) written off the tick loop.

Installed through :data:`~beastbt.runtime.session.PREPARE_HOOKS`: when a run
records (``RunOptions.record``, the default, into ``<run folder>/run.mcap``;
``--record FILE`` to that file as well, or instead with ``--no-record``), a
:class:`McapRecorder` is attached to the run:

* the tick side (``run.recorders``, an event log listener, ``run.send_servo``
  and the devices' polls, wrapped to note which device each reading came
  from) only takes references to the tick's immutable readings, poses and
  commands, copies the mutable ground truth, and appends one item to a
  bounded queue; it never serialises, compresses or touches the disk;
* a writer thread turns each item into JSON messages on the channels of
  :mod:`beastbt.runtime.recording_schemas`, and writes them with the ``mcap``
  library in compressed chunks, closing a chunk every ``chunk_interval_s`` of
  recorded clock time, so a run killed hard leaves a file that reads up to
  its last complete chunk (:func:`beastbt.runtime.recording_reader.read_recording`);
* when the queue is full: on a simulated clock the loop waits for the writer
  (nothing is lost, the simulation just runs slower); on the robot the item is
  dropped and counted, never blocking the loop. The summary gets
  ``recording: {messages, dropped}``.

The file also holds, for ``beastbt replay`` and ``beastbt report``: metadata
``beastbt.run`` (mission path, seed, robot profile, world, rate, capabilities,
servo names, the tree's nodes, the device polls), the mission, profile and
world files as attachments, the snapshots the run saved (JPEG attachments),
and at the end metadata ``beastbt.summary`` (the run summary).
"""

from __future__ import annotations

import base64
import collections
import dataclasses
import datetime as _dt
import json
import math
import threading
import time
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np
import yaml

from beastbt.blackboard.types import (BatteryState, CameraFrame, FusedPose, GpsFix, ImuSample, JoystickState,
                                      LineObservation, ServoCommand, VelocityCommand, WheelOdometry)
from beastbt.devices.dict_config import dataclass_from_dict
from beastbt.runtime import recording_schemas as rs
from beastbt.runtime.clock import SimClock

RECORDING_FORMAT = "beastbt-run/1"
"""Written in the ``beastbt.run`` metadata; bumped when the channels change incompatibly."""

MCAP_PROFILE = "beastbt"


# -- configuration -----------------------------------------------------------------------


@dataclass
class RecordingConfig:
    """How a run is recorded (``RunOptions.extras['recording']``; ``--record-images HZ`` sets image_rate_hz)."""

    # Camera frames stored as JPEG on /camera/image, frames per clock second (Hz). 0 turns images off;
    # every frame still gets a small /sensors/camera message. Raise it to see more, lower it for smaller files.
    image_rate_hz: float = 2.0
    # JPEG quality of recorded images, 1-100 (OpenCV's IMWRITE_JPEG_QUALITY).
    image_jpeg_quality: int = 75
    # Images wider than this are scaled down before encoding (pixels); 0 keeps the camera's size.
    image_max_width_px: int = 640
    # Ticks, events and servo commands waiting for the writer thread (items). ~200 s at 20 Hz; on the robot
    # an overflow drops items (counted in the summary), in the simulator the loop waits instead.
    queue_max_items: int = 4000
    # What a full queue does: "auto" (wait on a simulated clock, drop on the robot), "block" or "drop".
    overflow: str = "auto"
    # A chunk is closed and handed to the OS every this many clock seconds of records (s). A run killed
    # hard loses at most this much; shorter chunks compress less well.
    chunk_interval_s: float = 1.0
    # A chunk is also closed when its uncompressed size passes this (bytes), e.g. with many images.
    chunk_max_bytes: int = 4 * 1024 * 1024
    # Chunk compression: "auto" (zstd if installed, else lz4, else none), "zstd", "lz4" or "none".
    compression: str = "auto"
    # How long the end of a run waits for the writer to drain its queue before giving up (wall seconds).
    drain_timeout_s: float = 60.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.image_rate_hz) and self.image_rate_hz >= 0):
            raise ValueError(f"image_rate_hz must be zero or positive, got {self.image_rate_hz}")
        if not 1 <= self.image_jpeg_quality <= 100:
            raise ValueError(f"image_jpeg_quality must be 1-100, got {self.image_jpeg_quality}")
        if self.image_max_width_px < 0:
            raise ValueError(f"image_max_width_px must be zero or positive, got {self.image_max_width_px}")
        if self.queue_max_items < 1:
            raise ValueError(f"queue_max_items must be at least 1, got {self.queue_max_items}")
        if self.overflow not in ("auto", "block", "drop"):
            raise ValueError(f"overflow must be auto, block or drop, not '{self.overflow}'")
        if not (math.isfinite(self.chunk_interval_s) and self.chunk_interval_s > 0):
            raise ValueError(f"chunk_interval_s must be positive, got {self.chunk_interval_s}")
        if self.chunk_max_bytes < 1024:
            raise ValueError(f"chunk_max_bytes must be at least 1024, got {self.chunk_max_bytes}")
        if self.compression not in ("auto", "zstd", "lz4", "none"):
            raise ValueError(f"compression must be auto, zstd, lz4 or none, not '{self.compression}'")
        if not self.drain_timeout_s > 0:
            raise ValueError(f"drain_timeout_s must be positive, got {self.drain_timeout_s}")

    @classmethod
    def from_dict(cls, d: Any) -> "RecordingConfig":
        """Build from a dict; an unknown key or a bad value raises ``ValueError``."""
        return dataclass_from_dict(cls, d, "recording")


def compression_type(name: str) -> Any:
    """The ``mcap`` CompressionType for ``name`` (``auto`` picks zstd, then lz4, then none by what is installed)."""
    from mcap import writer as mw
    if name == "auto":
        name = "zstd" if mw.zstandard is not None else ("lz4" if mw.lz4 is not None else "none")
    return {"zstd": mw.CompressionType.ZSTD, "lz4": mw.CompressionType.LZ4,
            "none": mw.CompressionType.NONE}[name]


# -- conversions (writer thread) ----------------------------------------------------------


def ns(t_s: float) -> int:
    """Clock seconds to MCAP log time (integer nanoseconds, never negative)."""
    return max(0, int(round(t_s * 1e9)))


def _fox_time(t_ns: int) -> dict:
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def _json_default(o: Any) -> Any:
    """numpy scalars and arrays, tuples of them: what the JSON encoder does not know."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"cannot record a {type(o).__name__}")


_ENCODE = json.JSONEncoder(separators=(",", ":"), default=_json_default).encode


def gps_dict(r: GpsFix) -> dict:
    """GpsFix as its /sensors/gps message."""
    return {"stamp_s": r.stamp_s, "lat": r.lat, "lon": r.lon, "alt_msl": r.alt_msl, "quality": r.quality,
            "sats": r.sats, "hdop": r.hdop, "speed_mps": r.speed_mps, "track_deg": r.track_deg,
            "time_utc": r.time_utc, "sentence": r.sentence, "covariance_enu": [list(row) for row in r.covariance_enu]}


def imu_dict(r: ImuSample) -> dict:
    """ImuSample as its /sensors/imu message."""
    return {"stamp_s": r.stamp_s, "gyro_rps": list(r.gyro_rps), "accel_mps2": list(r.accel_mps2),
            "mag_t": list(r.mag_t) if r.mag_t is not None else None, "temperature_c": r.temperature_c}


def odometry_dict(r: WheelOdometry) -> dict:
    """WheelOdometry as its /sensors/odometry message."""
    return {"stamp_s": r.stamp_s, "left_m": r.left_m, "right_m": r.right_m, "left_mps": r.left_mps,
            "right_mps": r.right_mps}


def battery_dict(r: BatteryState) -> dict:
    """BatteryState as its /sensors/battery message."""
    return {"stamp_s": r.stamp_s, "voltage_v": r.voltage_v}


def joystick_dict(r: JoystickState) -> dict:
    """JoystickState as its /sensors/joystick message."""
    return {"stamp_s": r.stamp_s, "axes": dict(r.axes), "buttons": dict(r.buttons), "connected": r.connected}


def line_dict(r: LineObservation) -> dict:
    """LineObservation as its /sensors/line message."""
    return {"stamp_s": r.stamp_s, "seen": r.seen, "offset_m": r.offset_m, "angle_rad": r.angle_rad,
            "width_m": r.width_m, "confidence": r.confidence, "intersection": r.intersection,
            "intersection_distance_m": r.intersection_distance_m, "line_end": r.line_end}


def pose_dict(p: FusedPose) -> dict:
    """FusedPose as its /estimate/* message."""
    return {"stamp_s": p.stamp_s, "x": p.x, "y": p.y, "yaw": p.yaw, "speed_mps": p.speed_mps,
            "yaw_rate_rps": p.yaw_rate_rps, "covariance": [list(row) for row in p.covariance],
            "distance_m": p.distance_m, "heading_valid": p.heading_valid, "position_valid": p.position_valid,
            "lat": p.lat, "lon": p.lon}


def generic_dict(r: Any) -> dict:
    """A reading type without its own converter: its dataclass fields (arrays as lists)."""
    out = {}
    for f in dataclasses.fields(r):
        v = getattr(r, f.name)
        out[f.name] = v.tolist() if isinstance(v, np.ndarray) and v.size <= 64 else (
            None if isinstance(v, np.ndarray) else v)
    return out


_SENSOR_CONVERTERS: dict[type, tuple[str, Callable[[Any], dict]]] = {
    GpsFix: ("/sensors/gps", gps_dict), ImuSample: ("/sensors/imu", imu_dict),
    WheelOdometry: ("/sensors/odometry", odometry_dict), BatteryState: ("/sensors/battery", battery_dict),
    JoystickState: ("/sensors/joystick", joystick_dict), LineObservation: ("/sensors/line", line_dict),
}


def _snake(name: str) -> str:
    return "".join("_" + c.lower() if c.isupper() else c for c in name).lstrip("_")


def location_fix(r: GpsFix, t_ns: int) -> dict:
    """GpsFix as a foxglove.LocationFix (for Foxglove's map panel)."""
    return {"timestamp": _fox_time(t_ns), "frame_id": "gps", "latitude": r.lat, "longitude": r.lon,
            "altitude": r.alt_msl if r.alt_msl is not None else 0.0,
            "position_covariance": [float(v) for row in r.covariance_enu for v in row],
            "position_covariance_type": 1}


def pose_in_frame(p: FusedPose, t_ns: int, frame_id: str) -> dict:
    """FusedPose as a foxglove.PoseInFrame (planar pose, yaw about z)."""
    half = 0.5 * p.yaw
    return {"timestamp": _fox_time(t_ns), "frame_id": frame_id,
            "pose": {"position": {"x": p.x, "y": p.y, "z": 0.0},
                     "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)}}}


def stage_dict(tick: int, now_s: float, c: VelocityCommand, mux_source: str) -> dict:
    """A velocity command at one stage, with the tick it belongs to."""
    return {"tick": tick, "now_s": now_s, "linear_mps": c.linear_mps, "angular_rps": c.angular_rps,
            "stamp_s": c.stamp_s, "source": c.source, "mux_source": mux_source}


_LOG_LEVELS = {"failsafe": 3, "device_error": 4, "estop": 4, "step_failed": 3, "on_failure": 3,
               "recording": 3}


def log_level(kind: str) -> int:
    """foxglove.LogLevel of an event kind: WARNING/ERROR for faults, INFO otherwise."""
    level = _LOG_LEVELS.get(kind)
    if level is not None:
        return level
    return 3 if ("lost" in kind or "error" in kind) else 2


_UNSET = object()

WATCHED_DEVICE_FLAGS: list[tuple[str, str]] = [("imu_driver", "bias_ready")]
"""``(io.extras key, attribute)`` of device states that parts of the run read besides the readings (the
navigation estimator uses the IMU only once the driver's gyro bias is final); recorded on /devices/state
whenever they change, so that replay can give the estimator the same answers."""

TRUTH_FIELDS = ("t_s", "x", "y", "yaw", "v_mps", "w_rps", "left_m", "right_m", "pan_rad", "tilt_rad", "battery_v")


# -- the tick side's items ------------------------------------------------------------------


@dataclass(frozen=True)
class _Frame:
    """A camera frame as queued: its description, and its pixels only when it will be recorded as an image."""

    stamp_s: float
    seq: int
    width: int
    height: int
    image: Optional[np.ndarray]


class _TeeFile:
    """Writes the same bytes to several files; ``tell()`` of the first (the MCAP writer records offsets)."""

    def __init__(self, paths: list[Path]) -> None:
        self._files = []
        for p in paths:
            p.parent.mkdir(parents=True, exist_ok=True)
            self._files.append(open(p, "wb"))

    def write(self, data: bytes) -> int:
        for f in self._files:
            f.write(data)
        return len(data)

    def tell(self) -> int:
        return self._files[0].tell()

    def flush(self) -> None:
        for f in self._files:
            f.flush()

    def close(self) -> None:
        for f in self._files:
            f.close()


# -- the recorder -----------------------------------------------------------------------------


class McapRecorder:
    """Records one run into MCAP file(s): a cheap tick side, a writer thread, counts for the summary.

    ``paths``: the files to write (the same bytes to each). ``block_when_full``:
    wait for the writer when the queue is full (simulated clock) instead of
    dropping. ``info``: the ``beastbt.run`` metadata (strings); ``attachments``:
    ``(name, media type, bytes)`` stored at the start of the file.
    """

    def __init__(self, paths: list[Path], config: Optional[RecordingConfig] = None, block_when_full: bool = False,
                 info: Optional[dict] = None, attachments: Optional[list[tuple[str, str, bytes]]] = None) -> None:
        self.paths = [Path(p) for p in paths]
        self.config = config if config is not None else RecordingConfig()
        self.block_when_full = block_when_full
        self.info = {k: str(v) for k, v in (info or {}).items()}
        self.attachments = list(attachments or [])
        self.messages = 0
        """Messages written so far."""
        # Counted on two threads, so kept apart: a "+=" is not atomic across threads.
        self._dropped_tick_side = 0
        self._dropped_writer_side = 0
        self.dropped_items = 0
        self.writer_cpu_s = 0.0
        """CPU time the writer thread used (s), known once it has stopped."""
        self.error: Optional[str] = None
        """The writer's first error (the file may then be incomplete), or None."""
        self._queue: collections.deque = collections.deque()
        self._max = self.config.queue_max_items
        self._image_period_s = 1.0 / self.config.image_rate_hz if self.config.image_rate_hz > 0 else None
        self._next_image_s = -math.inf
        self._stopping = False
        self._wake = threading.Event()
        self._finished = False
        self._writer: Any = None
        self._stream: Optional[_TeeFile] = None
        self._channels: dict[str, int] = {}
        self._schema_ids: dict[str, int] = {}
        self._last_flush_s: Optional[float] = None
        self._thread = threading.Thread(target=self._run, name="beastbt-recorder", daemon=True)
        self._started = False
        self.run: Any = None
        """The MissionRun being recorded (set by :func:`install`), looked at once, at the first tick."""
        self._watched: list[tuple[str, str, Any]] = []
        self._flags: dict[tuple[str, str], Any] = {}
        self._tags: list[tuple[str, int]] = []
        """(device poll, readings it returned) in the order the loop polled this tick: who sent what."""
        self._base_tagged = False

    def tag_sources(self, io: Any) -> None:
        """Wrap the base's and every sensor's poll so each tick knows which device each reading came from.

        The base is wrapped on the adapter object itself (a watchdog wrapping it later still calls it);
        sensors in ``io.sensors``. Called when the recorder is installed and again at the first tick for
        sensors other parts added in between (their readings of tick 0 then have no known source).
        """
        if not self._base_tagged:
            try:
                io.base.poll = self._tagged("base", io.base.poll)
                self._base_tagged = True
            except (AttributeError, TypeError):
                pass
        for name, poll in list(io.sensors.items()):
            if not getattr(poll, "_beastbt_tagged", False):
                io.sensors[name] = self._tagged(str(name), poll)

    def _tagged(self, name: str, poll: Callable[[float], list]) -> Callable[[float], list]:
        tags = self._tags

        def tagged(now_s: float) -> list:
            out = poll(now_s)
            tags.append((name, len(out)))
            return out

        tagged._beastbt_tagged = True  # type: ignore[attr-defined]
        return tagged

    def _sources(self, n: int) -> Optional[list]:
        """This tick's reading sources in order (None when they do not add up), and forget them."""
        tags = self._tags
        if not tags:
            return None
        out: Optional[list] = []
        if sum(k for _, k in tags) != n:
            if not self._base_tagged and tags[0][0] != "base" and sum(k for _, k in tags) <= n:
                tags.insert(0, ("base", n - sum(k for _, k in tags)))  # the base polls first
            else:
                out = None
        if out is not None:
            for name, k in tags:
                out.extend([name] * k)
        tags.clear()
        return out

    @property
    def dropped(self) -> int:
        """Messages lost: queue overflow on the robot, or a writer failure."""
        return self._dropped_tick_side + self._dropped_writer_side

    # -- lifecycle ------------------------------------------------------------------------
    def start(self) -> "McapRecorder":
        """Start the writer thread (it opens the files and writes the header, metadata and attachments).

        :func:`install` leaves this to the first tick, so that the metadata
        sees the run as every prepare hook left it.
        """
        if not self._started:
            self._started = True
            if self.run is not None:
                self._snapshot_run(self.run)
            self._thread.start()
        return self

    def _snapshot_run(self, run: Any) -> None:
        """What the other parts did to the run after it was built, for replay; and the device flags to watch."""
        self.info["ctx_capabilities"] = json.dumps(sorted(run.ctx.capabilities))
        self.info["io_extras"] = json.dumps(sorted(str(k) for k in run.io.extras))
        self.info["tree"] = json.dumps(tree_nodes(run.root))
        self.tag_sources(run.io)
        self.info["sensor_sources"] = json.dumps(["base"] + [str(k) for k in run.io.sensors])
        for key, attr in WATCHED_DEVICE_FLAGS:
            device = run.io.extras.get(key)
            if device is not None and hasattr(device, attr):
                self._watched.append((key, attr, device))

    def stop(self) -> None:
        """No more items: let the writer drain the queue and close the last chunk (the file stays open)."""
        if not self._started:
            self.start()  # a run that never ticked still leaves a file (metadata, events)
        self._stopping = True
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(self.config.drain_timeout_s)
        if self._thread.is_alive():
            # The disk hangs: give up on what is queued rather than hang the end of the run.
            self.error = self.error or "the writer did not drain its queue in time"
            images = self._image_period_s is not None
            while self._queue:
                self._dropped_tick_side += _message_count(self._queue.popleft(), images)
                self.dropped_items += 1

    def finish(self, summary: Optional[dict] = None) -> None:
        """Stop if needed, store ``summary`` as metadata ``beastbt.summary``, write the MCAP summary and close."""
        if self._finished:
            return
        self.stop()
        self._finished = True
        if self._writer is None or self._thread.is_alive():
            return
        try:
            if summary is not None:
                self._writer.add_metadata("beastbt.summary", {"json": json.dumps(summary, default=_json_default)})
            self._writer.finish()
        except Exception as exc:
            self.error = self.error or f"finishing the file: {exc!r}"
        finally:
            try:
                if self._stream is not None:
                    self._stream.close()
            except Exception:
                pass

    # -- the tick side (cheap: references and one append) -------------------------------------
    def on_tick(self, rec: Any) -> None:
        """``run.recorders`` callable: queue what this tick did."""
        if not self._started:
            self.start()
        for key, attr, device in self._watched:
            value = getattr(device, attr)
            if self._flags.get((key, attr), _UNSET) != value:
                # A device state the estimator reads (the IMU's gyro bias being final): replay needs it.
                self._flags[(key, attr)] = value
                self._put(("flag", rec.tick, rec.now_s, key, attr, value))
        truth = rec.truth
        if truth is not None:
            truth = (truth.t_s, truth.x, truth.y, truth.yaw, truth.v_mps, truth.w_rps, truth.left_m, truth.right_m,
                     truth.pan_rad, truth.tilt_rad, truth.battery_v)
        readings = rec.readings
        for i, r in enumerate(readings):
            if r.__class__ is CameraFrame:
                # Hold the pixels only for frames that will be recorded: a lagging writer must not pin
                # seconds of full-rate video in memory.
                if readings is rec.readings:
                    readings = list(readings)
                image = r.image
                keep = self._image_period_s is not None and r.stamp_s >= self._next_image_s - 1e-9
                if keep:
                    step = self._image_period_s
                    self._next_image_s = (self._next_image_s + step if r.stamp_s - self._next_image_s < step
                                          else r.stamp_s + step)
                shape = getattr(image, "shape", (0, 0))
                readings[i] = _Frame(r.stamp_s, r.seq, int(shape[1]) if len(shape) > 1 else 0, int(shape[0]),
                                     image if keep else None)
        self._put(("tick", rec.tick, rec.now_s, readings, rec.pose_odom, rec.pose, rec.cmd_mission, rec.cmd_mux,
                   rec.cmd_gate, rec.mux_source, rec.changed_nodes, truth, self._sources(len(readings))))
        if len(self._queue) == 1:
            # The writer was idle: wake it now, at the end of the tick, so that on a paced loop it works
            # while the loop sleeps instead of waking at a random moment and competing with the next
            # tick for the GIL. (A busy writer finds the item by itself: no wake-up call to pay for.)
            self._wake.set()

    def on_event(self, ev: Any) -> None:
        """EventLog listener: queue the event (and it goes to /failsafes too when it is one)."""
        self._put(("event", ev.time_s, ev.kind, ev.text))

    def on_snapshot(self, path: str, stamp_s: float) -> None:
        """Queue a snapshot the run saved (a JPEG file): it becomes an attachment of the recording."""
        self._put(("snapshot", stamp_s, str(path)))

    def on_servo(self, cmd: ServoCommand, now_s: float) -> None:
        """Queue a servo command the run sent to its servo adapters."""
        self._put(("servo", now_s, cmd))

    def _put(self, item: tuple) -> None:
        q = self._queue
        if len(q) >= self._max:
            if self.block_when_full:
                # Simulated time does not run away: wait for the writer, lose nothing.
                self._wake.set()
                while len(q) >= self._max and self._thread.is_alive():
                    time.sleep(0.0005)
            if len(q) >= self._max:
                self.dropped_items += 1
                self._dropped_tick_side += _message_count(item, self._image_period_s is not None)
                return
        q.append(item)

    # -- the writer thread -------------------------------------------------------------------------
    def _run(self) -> None:
        cpu0 = time.thread_time()
        try:
            self._open()
        except Exception as exc:
            self.error = f"could not open the recording: {exc!r}"
            self._writer = None
        q = self._queue
        wake = self._wake
        while True:
            wake.wait(0.1)
            wake.clear()
            while q:
                item = q.popleft()
                if self._writer is None:
                    self._dropped_writer_side += _message_count(item, self._image_period_s is not None)
                    continue
                try:
                    self._write_item(item)
                except Exception as exc:
                    self.error = self.error or f"writing {item[0]}: {exc!r}"
                    self._dropped_writer_side += 1
                if item[0] == "tick":
                    # Let go of the GIL between ticks' worth of work: a tick waiting to start gets it now
                    # instead of after the interpreter's switch interval (5 ms).
                    time.sleep(0)
            if self._stopping and not q:
                break
        if self._writer is not None:
            try:
                self._writer.flush()
            except Exception as exc:
                self.error = self.error or f"flushing: {exc!r}"
        self.writer_cpu_s = time.thread_time() - cpu0

    def _open(self) -> None:
        from mcap.writer import Writer
        self._stream = _TeeFile(self.paths)
        w = Writer(self._stream, chunk_size=self.config.chunk_max_bytes,
                   compression=compression_type(self.config.compression))
        w.start(profile=MCAP_PROFILE, library=f"beastbt ({RECORDING_FORMAT})")
        w.add_metadata("beastbt.run", self.info)
        for name, media, data in self.attachments:
            w.add_attachment(create_time=0, log_time=0, name=name, media_type=media, data=data)
        self._writer = w
        # Every channel is declared up front (in a fixed order, so ids are the same run to run), even
        # those with no messages in this run: the file lists what a run of beastbt records.
        for topic in rs.CHANNELS:
            self._channel(topic)

    def _channel(self, topic: str, schema: Optional[dict] = None) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            schema = schema if schema is not None else rs.CHANNELS[topic]
            name = schema["title"]
            sid = self._schema_ids.get(name)
            if sid is None:
                sid = self._writer.register_schema(name=name, encoding="jsonschema", data=rs.schema_bytes(schema))
                self._schema_ids[name] = sid
            cid = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=sid)
            self._channels[topic] = cid
        return cid

    def _emit(self, topic: str, t_ns: int, obj: dict) -> None:
        cid = self._channels.get(topic)
        if cid is None:
            cid = self._channel(topic)
        self.messages += 1
        self._writer.add_message(channel_id=cid, log_time=t_ns, data=_ENCODE(obj).encode(), publish_time=t_ns,
                                 sequence=self.messages)

    def _write_item(self, item: tuple) -> None:
        kind = item[0]
        if kind == "tick":
            self._write_tick(item)
        elif kind == "event":
            _, time_s, ev_kind, text = item
            t = ns(time_s)
            ev = {"time_s": time_s, "kind": ev_kind, "text": text}
            self._emit("/events", t, ev)
            if ev_kind == "failsafe":
                self._emit("/failsafes", t, ev)
            self._emit("/log", t, {"timestamp": _fox_time(t), "level": log_level(ev_kind),
                                   "message": f"{ev_kind}: {text}", "name": ev_kind, "file": "", "line": 0})
        elif kind == "flag":
            _, tick, now_s, key, attr, value = item
            self._emit("/devices/state", ns(now_s), {"tick": tick, "now_s": now_s, "device": key, "field": attr,
                                                     "value": value})
        elif kind == "snapshot":
            _, stamp_s, path = item
            data = Path(path).read_bytes()
            self._writer.add_attachment(create_time=0, log_time=ns(stamp_s), name=Path(path).name,
                                        media_type="image/jpeg", data=data)
        elif kind == "servo":
            _, now_s, c = item
            self._emit("/cmd/servo", ns(now_s), {"now_s": now_s, "name": c.name, "angle_rad": c.angle_rad,
                                                 "channel": c.channel, "pulse_s": c.pulse_s, "stamp_s": c.stamp_s})

    def _write_tick(self, item: tuple) -> None:
        (_, tick, now_s, readings, pose_odom, pose, cmd_mission, cmd_mux, cmd_gate, mux_source, changed,
         truth, sources) = item
        t = ns(now_s)
        emit = self._emit
        for i, r in enumerate(readings):
            source = sources[i] if sources is not None else None
            conv = _SENSOR_CONVERTERS.get(r.__class__)
            if conv is not None:
                d = conv[1](r)
                d["source"] = source
                emit(conv[0], t, d)
                if r.__class__ is GpsFix:
                    emit("/gps/fix", t, location_fix(r, t))
            elif r.__class__ is _Frame:
                emit("/sensors/camera", t, {"stamp_s": r.stamp_s, "seq": r.seq, "width": r.width,
                                            "height": r.height, "image_recorded": r.image is not None,
                                            "source": source})
                if r.image is not None:
                    self._write_image(r, t)
            elif dataclasses.is_dataclass(r):
                name = type(r).__name__
                topic = rs.SENSOR_TOPICS.get(name, f"/sensors/{_snake(name)}")
                if topic not in self._channels:
                    self._channel(topic, {**rs.GENERIC_READING, "title": f"beastbt.{name}"})
                d = generic_dict(r)
                d.setdefault("source", source)
                emit(topic, t, d)
        if pose is not None:
            emit("/estimate/fused", t, pose_dict(pose))
            emit("/pose/fused", t, pose_in_frame(pose, t, "map"))
        if pose_odom is not None:
            emit("/estimate/odom", t, pose_dict(pose_odom))
        if cmd_mission is not None:
            emit("/cmd/mission", t, stage_dict(tick, now_s, cmd_mission, mux_source))
        if mux_source == "teleop":
            emit("/cmd/teleop", t, stage_dict(tick, now_s, cmd_mux, mux_source))
        emit("/cmd/mux", t, stage_dict(tick, now_s, cmd_mux, mux_source))
        emit("/cmd/gate", t, stage_dict(tick, now_s, cmd_gate, mux_source))
        if changed:
            emit("/tree", t, {"tick": tick, "now_s": now_s,
                              "changes": [{"name": n, "status": s, "feedback": f or ""} for n, s, f in changed]})
        if truth is not None:
            emit("/truth", t, dict(zip(TRUTH_FIELDS, truth)))
        last = self._last_flush_s
        if last is None:
            self._last_flush_s = now_s
        elif now_s - last >= self.config.chunk_interval_s - 1e-9:
            # Close the chunk and hand it to the OS: a hard kill now loses at most one interval.
            self._writer.flush()
            self._last_flush_s = now_s

    def _write_image(self, frame: _Frame, t_ns: int) -> None:
        import cv2  # only runs with a camera need it
        image = frame.image
        max_w = self.config.image_max_width_px
        if max_w and frame.width > max_w:
            h = max(1, int(round(frame.height * max_w / frame.width)))
            image = cv2.resize(image, (max_w, h), interpolation=cv2.INTER_AREA)
        ok, jpeg = cv2.imencode(".jpg", image, [int(cv2.IMWRITE_JPEG_QUALITY), self.config.image_jpeg_quality])
        if not ok:
            self._dropped_writer_side += 1
            return
        self._emit("/camera/image", t_ns, {"timestamp": _fox_time(t_ns), "frame_id": "camera",
                                           "data": base64.b64encode(jpeg.tobytes()).decode("ascii"),
                                           "format": "jpeg"})


def _message_count(item: tuple, images: bool) -> int:
    """How many messages an item would have made (for the dropped count)."""
    kind = item[0]
    if kind == "event":
        return 3 if item[2] == "failsafe" else 2
    if kind in ("servo", "flag", "snapshot"):
        return 1
    (_, _tick, _now, readings, pose_odom, pose, cmd_mission, _mux, _gate, mux_source, changed, truth, _src) = item
    n = 2  # mux, gate
    for r in readings:
        n += 2 if (r.__class__ is GpsFix or (r.__class__ is _Frame and r.image is not None)) else 1
    n += 2 * (pose is not None) + (pose_odom is not None) + (cmd_mission is not None)
    n += (mux_source == "teleop") + bool(changed) + (truth is not None)
    return n


def _record_servo_commands(run: Any, rec: McapRecorder) -> None:
    """Record every servo command the run sends (wrapping ``run.send_servo``, not the adapters, which
    other parts wrap for their own reasons: the watchdog's lock)."""
    send = run.send_servo

    def send_servo(cmd: ServoCommand, now_s: float) -> None:
        send(cmd, now_s)
        rec.on_servo(cmd, now_s)

    run.send_servo = send_servo


# -- what goes in the file besides the messages ---------------------------------------------------


def tree_nodes(root: Any) -> list[dict]:
    """The tree as a list (tick order, parents first): name, class, depth, leaf."""
    out: list[dict] = []

    def walk(node: Any, depth: int) -> None:
        out.append({"name": node.name, "kind": type(node).__name__, "depth": depth, "leaf": not node.children})
        for child in node.children:
            walk(child, depth + 1)

    walk(root, 0)
    return out


def _file_text(path: Optional[str], data: Any) -> Optional[str]:
    """The text of ``path`` when it still parses to ``data`` (what was run), else ``data`` as YAML."""
    if path:
        try:
            text = Path(path).read_text(encoding="utf-8")
            if data is None or yaml.safe_load(text) == data:
                return text
        except (OSError, yaml.YAMLError):
            pass
    if data is None:
        return None
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)


def run_info(prepared: Any) -> tuple[dict, list[tuple[str, str, bytes]]]:
    """The ``beastbt.run`` metadata and the attachments (mission, profile, world files) of a prepared run."""
    p = prepared
    run, opts, mission, profile, world = p.run, p.options, p.mission, p.profile, p.world
    mission_file = str(Path(mission.file).resolve()) if mission.file else ""
    info = {
        "format": RECORDING_FORMAT,
        "mission": mission.name,
        "mission_file": mission_file,
        "seed": opts.seed,
        "robot": opts.robot,
        "robot_profile": profile.name,
        "robot_profile_file": str(profile.file),
        "simulated": "true" if isinstance(p.clock, SimClock) else "false",
        "world": world.name if world is not None else "",
        "world_file": str(world.file) if world is not None and world.file else "",
        "rate_hz": repr(mission.rate_hz),
        "capabilities": json.dumps(sorted(run.io.capabilities)),
        "servo_names": json.dumps(sorted(run.io.servo_names())),
        "tree": json.dumps(tree_nodes(run.root)),
        "start_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "max_time_s": "" if opts.max_time_s is None else repr(opts.max_time_s),
    }
    if "magnetic_declination_deg" in run.io.extras:
        info["magnetic_declination_deg"] = repr(run.io.extras["magnetic_declination_deg"])
    if world is not None:
        info["world_start"] = json.dumps([world.start_x, world.start_y, world.start_yaw])
        info["world_datum"] = json.dumps([world.frame.lat0_deg, world.frame.lon0_deg, world.frame.alt0_m])
        info["world_walls"] = json.dumps([list(_wall_tuple(w)) for w in world.walls])
    attachments: list[tuple[str, str, bytes]] = []
    for name, path, data in (("mission.yaml", mission.file, mission.doc.data),
                             ("robot.yaml", profile.file, profile.data),
                             ("world.yaml", world.file if world is not None else None,
                              world.data if world is not None and world.file else None)):
        text = _file_text(path, data)
        if text is not None:
            attachments.append((name, "application/yaml", text.encode("utf-8")))
    return info, attachments


def _wall_tuple(w: Any) -> tuple:
    """A wall segment as (x1, y1, x2, y2) metres."""
    return (float(w.x1), float(w.y1), float(w.x2), float(w.y2))


# -- installation: the prepare hook, the summary, the CLI option ---------------------------------------

_RECORDERS: "weakref.WeakKeyDictionary[Any, McapRecorder]" = weakref.WeakKeyDictionary()


def recorder_of(run: Any) -> Optional[McapRecorder]:
    """The recorder attached to a :class:`~beastbt.runtime.runner.MissionRun`, if it records."""
    return _RECORDERS.get(run)


def config_from_options(opts: Any) -> RecordingConfig:
    """The recording config of a run: ``extras['recording']`` (a dict), ``extras['record_images']`` (Hz)."""
    cfg = dict(opts.extras.get("recording") or {})
    hz = opts.extras.get("record_images")
    if hz is not None:
        cfg["image_rate_hz"] = float(hz)
    return RecordingConfig.from_dict(cfg)


def install(prepared: Any) -> Optional[McapRecorder]:
    """PREPARE_HOOK: attach a recorder to the run when it records (run folder and/or ``--record FILE``)."""
    opts = prepared.options
    paths: list[Path] = []
    if prepared.folder is not None:
        paths.append(Path(prepared.folder.path) / "run.mcap")
    if opts.record_path:
        target = Path(opts.record_path)
        if not paths or target.resolve() != paths[0].resolve():
            paths.append(target)
    if not paths:
        return None
    config = config_from_options(opts)
    block = config.overflow == "block" or (config.overflow == "auto" and isinstance(prepared.clock, SimClock))
    info, attachments = run_info(prepared)
    rec = McapRecorder(paths, config, block_when_full=block, info=info, attachments=attachments)
    run = prepared.run
    # Events from before this hook (device warnings while the robot was assembled) go first.
    for ev in list(run.events.events):
        rec.on_event(ev)
    run.recorders.append(rec.on_tick)
    run.events.listeners.append(rec.on_event)
    _record_servo_commands(run, rec)
    save = run.ctx.services.get("save_snapshot")
    if save is not None:
        def save_and_record(name: str, frame: Any) -> str:
            path = save(name, frame)
            rec.on_snapshot(path, getattr(frame, "stamp_s", 0.0))
            return path

        run.ctx.services["save_snapshot"] = save_and_record
    rec.tag_sources(run.io)
    rec.run = run
    _RECORDERS[run] = rec
    prepared.closers.append(rec.stop)
    if prepared.folder is not None:
        prepared.folder.finishers.append(rec.finish)
    else:
        prepared.closers.append(rec.finish)
    return rec


def contribute_summary(run: Any, summary: dict) -> None:
    """SUMMARY_CONTRIBUTOR: ``recording: {messages, dropped}`` (no path: the summary stays the same run to run)."""
    rec = _RECORDERS.get(run)
    if rec is None:
        return
    entry: dict = {"messages": rec.messages, "dropped": rec.dropped}
    if rec.error:
        entry["error"] = rec.error
    summary["recording"] = entry


def add_run_options(p: Any) -> None:
    """``beastbt run --record-images HZ``."""
    p.add_argument("--record-images", type=float, metavar="HZ", dest="record_images",
                   help="camera images recorded per second as JPEG (default 2; 0 for none)")


def register() -> None:
    """Install the hook, the summary contributor and the run option (once)."""
    from beastbt import cli
    from beastbt.runtime.session import PREPARE_HOOKS
    from beastbt.runtime.summary import SUMMARY_CONTRIBUTORS
    if install not in PREPARE_HOOKS:
        PREPARE_HOOKS.append(install)
    if contribute_summary not in SUMMARY_CONTRIBUTORS:
        SUMMARY_CONTRIBUTORS.append(contribute_summary)
    if add_run_options not in cli.RUN_OPTIONS:
        cli.RUN_OPTIONS.append(add_run_options)


register()

__all__ = ["RecordingConfig", "McapRecorder", "install", "recorder_of", "contribute_summary", "run_info",
           "tree_nodes", "ns", "compression_type", "RECORDING_FORMAT"]
