"""Every run recorded: an MCAP file (``run.mcap``) written by a separate process, off the tick loop.

Installed by the assembly (:func:`install`) into every run that records: when a run
records (``RunOptions.record``, the default, into ``<run folder>/run.mcap``;
``--record FILE`` to that file as well, or instead with ``--no-record``), a
:class:`McapRecorder` is attached to the run:

* the tick side (``run.recorders``, an event log listener, ``run.send_servo``
  and the devices' polls, wrapped to note which device each reading came
  from) turns each tick's readings, poses and commands into bytes with
  :mod:`pickle` (:mod:`beastbt.recording.wire`, a few microseconds)
  and writes them into a pipe, a batch at a time; it never builds JSON,
  compresses or touches the disk;
* what goes, and how often: the readings the run used (:data:`READING_KEYS`:
  nothing is woken for the recording, and readings nobody reads are left
  out, unless ``--record-sensors``), the commands and the tree's changes
  every tick, the poses and the truth at ``pose_rate_hz`` and every
  ``still_interval_s`` while nothing moves (:meth:`McapRecorder._pose_due`);
* the writer process (:mod:`beastbt.recording.writer`, started when
  the recorder is installed) does all of that on another core, under its
  own interpreter lock, so recording does not slow the loop even when the
  simulator runs flat out. Its chunks close every ``chunk_interval_s`` of
  recorded clock time, each followed by a valid end, so a run killed hard
  leaves a valid MCAP file that reads up to its last complete chunk (with
  ``mcap``'s readers and :func:`beastbt.recording.reader.read_recording`;
  ``beastbt recover`` for a torn one); when only the run's process dies, the
  writer sees the pipe end and closes the file properly;
* what the writer says unasked (a file it stopped writing: a full disk) is
  looked for between ticks (:meth:`McapRecorder.poll_notices`) and becomes a
  ``recording`` event at once; the free space where the recording goes is
  checked at the start (``min_free_mb``);
* the queue is bounded: the pipe (up to 1 MiB) and at most
  ``queue_max_items`` items waiting for it. When it is full: on a simulated
  clock the loop waits for the writer (nothing is lost, the simulation just
  runs slower); on the robot the item is dropped and counted, never blocking
  the loop. The summary gets ``recording: {messages, dropped}``.

The file also holds, for ``beastbt replay`` and ``beastbt report``: metadata
``beastbt.run`` (mission path, seed, robot profile, world, rate, capabilities,
servo names, the tree's nodes, the device polls), the mission, profile and
world files as attachments, the snapshots the run saved (JPEG attachments),
and at the end metadata ``beastbt.summary`` (the run summary).
"""

from __future__ import annotations

import collections
import dataclasses
import datetime as _dt
import json
import os
import select
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable, Optional

import yaml

import beastbt
from beastbt.blackboard.types import (BatteryState, CameraFrame, GpsFix, ImuSample, JoystickState, LaserScan,
                                      ServoCommand)
from beastbt.core.clock import SimClock
from beastbt.recording.config import FramesConfig, RecordingConfig, compression_type
from beastbt.recording.obstacle_views import ObstacleSampler
from beastbt.recording.scene import scene_description
from beastbt.recording.wire import Frame, ItemEncoder
from beastbt.recording.writer import (MCAP_PROFILE, OFFSET_KEY, RECORDING_FORMAT, TRUTH_FIELDS,
                                     json_default, message_count, ns, reading_sources)

_UNSET = object()

WATCHED_DEVICE_FLAGS: list[tuple[str, str]] = [("imu_driver", "bias_ready")]
"""``(RobotIO device name, attribute)`` of device states that parts of the run read besides the readings (the
navigation estimator uses the IMU only once the driver's gyro bias is final); recorded on /devices/state
whenever they change, so that replay can give the estimator the same answers."""

READING_KEYS: dict[type, str] = {ImuSample: "imu", GpsFix: "gps_fix", BatteryState: "battery",
                                 JoystickState: "joystick", LaserScan: "scan"}
"""Reading type -> the key a run reads it by. A reading whose key nothing in the run reads (the base's IMU
samples while the EKF sleeps) is left out of the recording unless ``--record-sensors``: replay does not need
it, nothing used it. Wheel odometry (the run's own dead reckoning), camera frames and line observations (the
camera and its detector run only when someone wants them) and types not listed are always kept."""

BATCH_ITEMS = 64
"""A batch goes into the pipe once it holds this many items, whatever its age."""

PIPE_BYTES = 1 << 20
"""Size asked of the pipe to the writer process (bytes; Linux grants up to ``/proc/sys/fs/pipe-max-size``)."""

_WRITER_START = ("import sys; root = sys.argv[1]; root in sys.path or sys.path.insert(0, root); "
                 "from beastbt.recording.writer import main; main()")
"""How the writer process starts: this very beastbt (a checkout on ``sys.path`` too), its ``main()``."""


WRITER_THREADS_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
"""Thread-pool sizes set to 1 for the writer process: it does no linear algebra, and numpy's import starts an
OpenBLAS pool of one thread per core that spins as it starts (about 0.1 s of CPU here, taken from the tick loop
on a busy machine: a third of the writer's whole cost in a 3500-tick run)."""


def writer_environment() -> dict[str, str]:
    """The environment of the writer process: this process's, with the thread pools of :data:`WRITER_THREADS_ENV`
    at one thread."""
    env = dict(os.environ)
    env.update({name: "1" for name in WRITER_THREADS_ENV})
    return env


def low_space_warnings(paths: list[Path], min_free_mb: float) -> list[str]:
    """A warning for each folder of ``paths`` with less than ``min_free_mb`` megabytes (10^6 bytes) free."""
    out = []
    for folder in dict.fromkeys(Path(p).resolve().parent for p in paths):
        try:
            free_mb = shutil.disk_usage(folder).free / 1e6
        except OSError:
            continue  # not there yet (the writer makes it) or not ours to look at: the writer will say
        if free_mb < min_free_mb:
            out.append(f"only {free_mb:.1f} MB free at {folder} (recording min_free_mb: {min_free_mb:g} MB): "
                       f"when the disk fills, the recording stops and the mission goes on")
    return out


def _grow_pipe(fd: int) -> None:
    """Ask for a pipe of PIPE_BYTES (Linux): fewer waits and drops when the writer lags a moment."""
    try:
        import fcntl
        fcntl.fcntl(fd, getattr(fcntl, "F_SETPIPE_SZ", 1031), PIPE_BYTES)
    except (ImportError, OSError):
        pass  # not Linux, or above the system's limit: the default pipe (64 KiB) still works


# -- the recorder -----------------------------------------------------------------------------


class McapRecorder:
    """Records one run into MCAP file(s): a cheap tick side, a writer process, counts for the summary.

    ``paths``: the files to write (the same bytes to each; none when the run
    is only served live). ``live``: (host, port) of a Foxglove WebSocket
    server the writer process runs with the same messages
    (:mod:`beastbt.recording.foxglove_live`). ``block_when_full``:
    wait for the writer when the queue is full (simulated clock) instead of
    dropping. ``info``: the ``beastbt.run`` metadata (strings); ``attachments``:
    ``(name, media type, bytes)`` stored at the start of the file.
    """

    def __init__(self, paths: list[Path], config: Optional[RecordingConfig] = None, block_when_full: bool = False,
                 info: Optional[dict] = None, attachments: Optional[list[tuple[str, str, bytes]]] = None,
                 live: Optional[tuple[str, int]] = None) -> None:
        self.paths = [Path(p) for p in paths]
        self.live = live
        """(host, port) where the writer process serves the channels to Foxglove live, or None."""
        self.config = config if config is not None else RecordingConfig()
        self.block_when_full = block_when_full
        self.info = {k: str(v) for k, v in (info or {}).items()}
        self.attachments = list(attachments or [])
        self.messages = 0
        """Messages written (known once the writer has answered :meth:`stop`)."""
        self._dropped_tick_side = 0
        self._dropped_writer_side = 0
        self.dropped_items = 0
        """Items the tick side dropped (a full queue on the robot, or no writer to take them)."""
        self.writer_cpu_s = 0.0
        """CPU time the writer process used (s), known once it has answered :meth:`stop`."""
        self.error: Optional[str] = None
        """The first error (the file may then be incomplete), or None."""
        self._max = self.config.queue_max_items
        self._image_period_s = 1.0 / self.config.image_rate_hz if self.config.image_rate_hz > 0 else None
        self._next_image_s = float("-inf")
        self._encoder = ItemEncoder()
        self._pending: collections.deque = collections.deque()
        """``(bytes, items)`` not yet in the pipe, oldest first; the first may be partly written."""
        self._pending_items = 0
        self._batch_items: list[tuple] = []
        """Items not yet encoded: one pickle and one write per batch, not per item."""
        self._batch_t0 = 0.0
        self._proc: Optional[subprocess.Popen] = None
        self._fd: Optional[int] = None
        self._doorbell: Optional[int] = None
        """Write end of the writer's doorbell: rung when the run waits for an answer (see the writer's
        ``_polling_reader``)."""
        self._reply_buffer = b""
        self._last_poll_s = float("-inf")
        """Clock time (s) the writer's notices were last looked for."""
        self._gone = False
        """The writer process cannot take more (it never started, died, or was given up on)."""
        self._started = False
        self._stopped = False
        self._finished = False
        self.run: Any = None
        """The MissionRun being recorded (set by :func:`install`), looked at once, at the first tick."""
        self._watched: list[tuple[str, str, Any]] = []
        self._flags: dict[tuple[str, str], Any] = {}
        self._tags: list[tuple[str, int]] = []
        """(device poll, readings it returned) in the order the loop polled this tick: who sent what."""
        self._base_tagged = False
        self._unused: frozenset = frozenset()
        """Reading types left out (nothing in the run reads them): see :meth:`keep_only_used`."""
        self.vision_answers: Any = None
        """What the detectors answered the mission (:class:`~beastbt.vision.recorded_answers.AnswerTap`), for replay;
        None when the mission does not ask the camera."""
        self._pose_period_s = 1.0 / self.config.pose_rate_hz if self.config.pose_rate_hz > 0 else 0.0
        self._pose_s = float("-inf")
        """Clock time (s) the poses last went to the recording."""
        self._pose_key: Any = None
        """Where the poses and the true pose were then (to see whether anything moved)."""
        self._servo_moved = False
        self._views: Optional[ObstacleSampler] = None
        """What the obstacle views draw (costmap, plan, zones, persons), sampled each tick once ``run`` is known."""
        self._detections: Any = None
        """The detectors' frame entries (:mod:`beastbt.vision.detection_feed`), once the run's vision watch is seen."""

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

    def keep_only_used(self, reads: Optional[frozenset]) -> None:
        """Leave out the readings whose key (:data:`READING_KEYS`) is not in ``reads`` (what the run and its awake
        parts read); None keeps every reading."""
        self._unused = frozenset() if reads is None else frozenset(
            cls for cls, key in READING_KEYS.items() if key not in reads)

    def _tagged(self, name: str, poll: Callable[[float], list]) -> Callable[[float], list]:
        tags = self._tags

        def tagged(now_s: float) -> list:
            out = poll(now_s)
            tags.append((name, len(out)))
            return out

        tagged._beastbt_tagged = True  # type: ignore[attr-defined]
        return tagged

    def _take_tags(self) -> tuple[bool, tuple]:
        """This tick's (device, readings) tags, and whether the base's poll is among the tagged; forgets them.

        The writer process turns them into each reading's source
        (:func:`~beastbt.recording.writer.reading_sources`).
        """
        tags = self._tags
        out = (self._base_tagged, tuple(tags))
        tags.clear()
        return out

    @property
    def dropped(self) -> int:
        """Messages lost: queue overflow on the robot, or a writer failure."""
        return self._dropped_tick_side + self._dropped_writer_side

    # -- lifecycle ------------------------------------------------------------------------
    def launch(self) -> "McapRecorder":
        """Start the writer process (it imports while the run gets ready; it writes nothing before :meth:`start`)."""
        if self._proc is not None or self._gone:
            return self
        root = str(Path(beastbt.__file__).resolve().parent.parent)
        bell_w: Optional[int] = None
        try:
            bell_r, bell_w = os.pipe()
            try:
                self._proc = subprocess.Popen([sys.executable, "-c", _WRITER_START, root, str(bell_r)],
                                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, close_fds=True,
                                              pass_fds=(bell_r,), env=writer_environment())
            finally:
                os.close(bell_r)
            fd = self._proc.stdin.fileno()
            os.set_blocking(self._proc.stdout.fileno(), False)  # notices are looked for between ticks
            _grow_pipe(fd)
            os.set_blocking(fd, False)  # the loop never waits on the pipe unless told to (block_when_full)
            os.set_blocking(bell_w, False)
        except (OSError, ValueError) as exc:  # no subprocess here, or a platform without these pipe calls
            if bell_w is not None:
                os.close(bell_w)
            self._give_up(f"could not start the writer process: {exc!r}")
            return self
        self._fd = fd
        self._doorbell = bell_w
        return self

    def start(self, now_s: float = 0.0) -> "McapRecorder":
        """Open the file: the writer gets the metadata and attachments, then what was queued so far.

        :func:`install` leaves this to the first tick, so that the metadata
        sees the run as every prepare hook left it. ``now_s``: the run's
        clock then (s); with the wall time now it fixes the log times' epoch
        (metadata ``log_time_offset_ns``) unless ``info`` gave one.
        """
        if self._started:
            return self
        self._started = True
        # Log times are Unix epoch ns (Foxglove, other tools and other runs line up): the simulator's clock
        # starts at the wall time of its first tick, the robot's monotonic clock keeps its pace from there.
        self.info.setdefault(OFFSET_KEY, str(time.time_ns() - ns(now_s)))
        if self.run is not None:
            self._snapshot_run(self.run)
        self.launch()
        opening = ("open", [str(p) for p in self.paths], dataclasses.asdict(self.config), dict(self.info),
                   [(n, m, bytes(d)) for n, m, d in self.attachments], self.live)
        self._pending.appendleft((self._encoder.encode([opening]), ()))
        self._send_batch()
        self._pump(block=False)
        for text in low_space_warnings(self.paths, self.config.min_free_mb):
            self._tell(text, error=False)  # now, at the first tick: the terminal and the console show the run's events
        return self

    def _snapshot_run(self, run: Any) -> None:
        """What the other parts did to the run after it was built, for replay; and the device flags to watch."""
        self.info["ctx_capabilities"] = json.dumps(sorted(run.ctx.capabilities))
        # Named io_extras in recordings made before the devices were typed fields; replay reads both alike.
        self.info["io_extras"] = json.dumps(sorted(run.io.devices()))
        self.info["tree"] = json.dumps(tree_nodes(run))
        self.tag_sources(run.io)
        self.info["sensor_sources"] = json.dumps(["base"] + [str(k) for k in run.io.sensors])
        inputs = getattr(run, "inputs", None)
        if inputs is not None:  # the operator's channels (a console can drive the robot by hand): replay opens them
            self.info["operator_inputs"] = json.dumps(sorted(inputs.sources))
        for key, attr in WATCHED_DEVICE_FLAGS:
            device = getattr(run.io, key, None)
            if device is not None and hasattr(device, attr):
                self._watched.append((key, attr, device))
    def stop(self) -> None:
        """No more items: the writer writes everything queued, closes its chunk and reports its counts.

        The file stays open for :meth:`finish`. Waits at most ``drain_timeout_s``
        (wall time) for the writer, then gives up on what is still queued.
        """
        if self._stopped:
            return
        clock = getattr(self.run, "clock", None)
        # A run that never ticked still leaves a file (metadata, events).
        self.start(clock.now() if clock is not None else 0.0)
        self._stopped = True
        if self._gone:
            return
        deadline = time.monotonic() + self.config.drain_timeout_s
        self._send_batch()
        self._pending.append((self._encoder.encode([("stop",)]), ()))
        if self._pump(block=True, deadline=deadline):
            self._take_reply(deadline)
        elif not self._gone:
            # The disk hangs (the writer stopped reading): give up on what is queued rather than hang the run.
            self._give_up("the writer did not drain its queue in time")

    def finish(self, summary: Optional[dict] = None) -> None:
        """Stop if needed, store ``summary`` as metadata ``beastbt.summary``, let the writer close the file."""
        if self._finished:
            return
        self.stop()
        self._finished = True
        proc = self._proc
        if proc is None:
            return
        if not self._gone:
            deadline = time.monotonic() + self.config.drain_timeout_s
            summary_json = json.dumps(summary, default=json_default) if summary is not None else None
            self._pending.append((self._encoder.encode([("finish", summary_json)]), ()))
            if self._pump(block=True, deadline=deadline):
                self._take_reply(deadline)
        self._close_pipe()
        try:
            # The writer ends right after its last answer; a hung one is not waited for.
            proc.wait(timeout=self.config.drain_timeout_s if not self._gone else 1.0)
        except subprocess.TimeoutExpired:
            self.error = self.error or "the writer did not close the file in time"
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()

    # -- the tick side (cheap: a pickle, and now and then a write into the pipe) ---------------
    def on_tick(self, rec: Any) -> None:
        """``run.recorders`` callable: queue what this tick did (and look for the writer's notices)."""
        if not self._started:
            self.start(rec.now_s)
        if rec.now_s - self._last_poll_s >= self.config.send_interval_s:
            self._last_poll_s = rec.now_s
            self.poll_notices()
        for key, attr, device in self._watched:
            value = getattr(device, attr)
            if self._flags.get((key, attr), _UNSET) != value:
                # A device state the estimator reads (the IMU's gyro bias being final): replay needs it.
                self._flags[(key, attr)] = value
                self._put(("flag", rec.tick, rec.now_s, key, attr, value), rec.now_s)
        pose_odom, pose, truth = rec.pose_odom, rec.pose, rec.truth
        if not self._pose_due(rec.now_s, pose_odom, pose, truth):
            pose_odom = pose = truth = None  # not this tick: the poses go at pose_rate_hz, and rarer standing still
        elif truth is not None:
            truth = (truth.t_s, truth.x, truth.y, truth.yaw, truth.v_mps, truth.w_rps, truth.left_m, truth.right_m,
                     truth.pan_rad, truth.tilt_rad, truth.battery_v)
        readings = rec.readings
        tags = self._take_tags()
        skip = self._unused
        if skip and readings:
            readings, tags = _used_only(readings, tags, skip)
        for i, r in enumerate(readings):
            if r.__class__ is CameraFrame:
                # Pixels go down the pipe only for frames that will be recorded as images.
                if readings is rec.readings:
                    readings = list(readings)
                image = r.image
                keep = self._image_period_s is not None and r.stamp_s >= self._next_image_s - 1e-9
                if keep:
                    step = self._image_period_s
                    self._next_image_s = (self._next_image_s + step if r.stamp_s - self._next_image_s < step
                                          else r.stamp_s + step)
                shape = getattr(image, "shape", (0, 0))
                readings[i] = Frame(r.stamp_s, r.seq, int(shape[1]) if len(shape) > 1 else 0, int(shape[0]),
                                    image if keep else None, r.jpeg if keep else None)
        self._put(("tick", rec.tick, rec.now_s, readings, pose_odom, pose, rec.cmd_mission, rec.cmd_mux,
                   rec.cmd_gate, rec.mux_source, rec.changed_nodes, truth, tags), rec.now_s)
        if self.vision_answers is not None:
            answers = self.vision_answers.take()
            if answers:  # what the detectors answered this tick: replay gives it back (/vision/answers)
                self._put(("vision_answers", rec.now_s, answers), rec.now_s)
        views = self._views
        if views is None and self.run is not None:
            views = self._views = ObstacleSampler(self.run)
        if views is not None:
            changed = views.sample(rec.now_s)
            if changed is not None:
                self._put(("views", rec.now_s, changed), rec.now_s)
        if self._detections is None and self.run is not None:
            watch = getattr(self.run.ctx.services, "vision", None)
            if watch is not None:  # the mission uses the camera's words: the detectors may wake
                from beastbt.vision.detection_feed import DetectionFeed
                self._detections = DetectionFeed.attach(watch)
        if self._detections is not None:
            entries = self._detections.take(rec.now_s)
            if entries:
                self._put(("detections", rec.now_s, entries), rec.now_s)

    def _pose_due(self, now_s: float, pose_odom: Any, pose: Any, truth: Any) -> bool:
        """Whether this tick's poses (and truth) go to the recording: at most ``pose_rate_hz``, and while nothing
        moves (the poses, the true pose, the gimbal) only every ``still_interval_s``.

        What is drawn from the poses (/odom, /tf, /estimate/*) needs no more: the tick's commands and the
        readings the run used, which replay needs, go every tick whatever this says.
        """
        if pose_odom is None and pose is None and truth is None:
            return False
        since = now_s - self._pose_s
        if since < self._pose_period_s - 1e-9:
            return False
        key = (None if pose_odom is None else (pose_odom.x, pose_odom.y, pose_odom.yaw),
               None if pose is None else (pose.x, pose.y, pose.yaw, pose.position_valid),
               None if truth is None else (truth.x, truth.y, truth.yaw))
        if key == self._pose_key and not self._servo_moved and since < self.config.still_interval_s - 1e-9:
            return False
        self._pose_key, self._pose_s, self._servo_moved = key, now_s, False
        return True

    def on_event(self, ev: Any) -> None:
        """EventLog listener: queue the event (and it goes to /failsafes too when it is one)."""
        # At once, with whatever is batched: the moments before a fault are the ones worth keeping.
        self._put(("event", ev.time_s, ev.kind, ev.text), ev.time_s, urgent=True)

    def on_input(self, item: Any) -> None:
        """``run.inputs`` listener: queue an operator input (:class:`~beastbt.run.operator_inputs.OperatorInput`)."""
        self._put(("input", item.tick, item.now_s, item.source, item.control, dict(item.body)), item.now_s,
                  urgent=True)

    def on_snapshot(self, path: str, stamp_s: float) -> None:
        """Queue a snapshot the run saved (a JPEG file): it becomes an attachment of the recording."""
        self._put(("snapshot", stamp_s, str(path)), stamp_s)

    def on_scene(self, description: dict, now_s: float) -> None:
        """Queue what the run happens in (:func:`~beastbt.recording.scene.scene_description`): /scene, /route."""
        self._put(("scene", now_s, description), now_s)

    def on_servo(self, cmd: ServoCommand, now_s: float) -> None:
        """Queue a servo command the run sent to its servo adapters (the gimbal moved: /tf goes at its next turn)."""
        self._servo_moved = True
        self._put(("servo", now_s, cmd), now_s)

    # -- the queue and the pipe -------------------------------------------------------------------
    def _put(self, item: tuple, now_s: float, urgent: bool = False) -> None:
        """Queue an item made at clock time ``now_s``. It joins the batch (a reference, no copy: readings
        are immutable), and the batch goes into the pipe when it is ``send_interval_s`` old or
        BATCH_ITEMS long, or at once when ``urgent``."""
        if self._gone:
            self._count_dropped(item)
            return
        if self._pending_items + len(self._batch_items) >= self._max and (self._started or not self.block_when_full):
            # (Before the writer starts, in the simulator, the few set-up items wait in the batch: none is lost.)
            if self.block_when_full:
                # Simulated time does not run away: wait for the writer, lose nothing.
                self._send_batch()
                self._pump(block=True, keep=self._max - 1)
            if self._gone or self._pending_items + len(self._batch_items) >= self._max:
                self._count_dropped(item)
                return
        batch = self._batch_items
        if not batch:
            self._batch_t0 = now_s
        batch.append(item)
        if self._started and (urgent or now_s - self._batch_t0 >= self.config.send_interval_s
                              or len(batch) >= BATCH_ITEMS):
            self._send_batch()

    def _send_batch(self) -> None:
        """Encode the batch (one pickle) and move it into the pipe (what does not fit now waits in the queue)."""
        items = self._batch_items
        if not items:
            return
        self._batch_items = []
        try:
            data = self._encoder.encode(items)
        except Exception:
            data = self._encode_one_by_one(items)
        self._pending.append((data, items))
        self._pending_items += len(items)
        self._pump(block=False)

    def _encode_one_by_one(self, items: list[tuple]) -> bytes:
        """A batch pickle refused: encode item by item, dropping (and counting) those it refuses."""
        parts = []
        for item in items:
            try:
                parts.append(self._encoder.encode([item]))
            except Exception as exc:
                self.error = self.error or f"cannot record a {item[0]}: {exc!r}"
                self._count_dropped(item)
        return b"".join(parts)

    def _pump(self, block: bool, keep: int = 0, deadline: Optional[float] = None) -> bool:
        """Move queued bytes into the pipe until at most ``keep`` items wait: as far as the pipe takes them now,
        or waiting for the writer (``block``, until ``deadline`` on the monotonic clock when given).
        True when done."""
        pending = self._pending
        while pending and (keep == 0 or self._pending_items > keep):
            if self._gone:
                return False
            data, items = pending[0]
            try:
                n = os.write(self._fd, data)
            except BlockingIOError:
                n = 0
            except OSError as exc:
                self._give_up(f"the writer process is gone ({exc.strerror or exc!r})")
                return False
            if n == len(data):
                pending.popleft()
                self._pending_items -= len(items)
                continue
            if n:
                pending[0] = (memoryview(data)[n:], items)
            if not block or not self._wait_writable(deadline):
                return False
        return True

    def _wait_writable(self, deadline: Optional[float]) -> bool:
        """Wait (50 ms at a time) until the pipe takes bytes; False once past ``deadline`` or the writer died."""
        self._ring()
        while True:
            _, ready, _ = select.select([], [self._fd], [], 0.05)
            if ready:
                return True
            if self._proc is None or self._proc.poll() is not None:
                self._give_up("the writer process ended early")
                return False
            if deadline is not None and time.monotonic() > deadline:
                return False

    def _next_line(self) -> Optional[dict]:
        """The next whole line from the writer, decoded; notices (``{"notice": text}``) are told, not returned."""
        while b"\n" in self._reply_buffer:
            line, self._reply_buffer = self._reply_buffer.split(b"\n", 1)
            answer = json.loads(line)
            if "notice" in answer:
                self._tell(str(answer["notice"]))
                continue
            return answer
        return None

    def _read_writer(self) -> bool:
        """Add what the writer said so far to the buffer, without waiting; False when it is gone."""
        try:
            chunk = os.read(self._proc.stdout.fileno(), 65536)
        except BlockingIOError:
            return True
        except (OSError, ValueError):
            return False
        self._reply_buffer += chunk
        return bool(chunk)

    def poll_notices(self) -> None:
        """Tell the run what the writer said unasked (a file it stopped writing: a full disk); never waits."""
        if self._proc is None or self._proc.stdout is None or self._proc.stdout.closed:
            return
        self._read_writer()
        if self._reply_buffer:
            leftover = self._next_line()
            if leftover is not None:  # not expected unasked: keep it for the next answer
                self._reply_buffer = (json.dumps(leftover) + "\n").encode() + self._reply_buffer

    def _tell(self, text: str, error: bool = True) -> None:
        """A notice becomes an event of the run (terminal, console, summary) and, when an ``error``, the error."""
        if error:
            self.error = self.error or text
        events = getattr(self.run, "events", None)
        if events is not None:
            events.add("recording", text)
        else:
            print(f"beastbt: {text}", file=sys.stderr, flush=True)

    def _take_reply(self, deadline: float) -> None:
        """Read the writer's next answer (a JSON line: messages, dropped, error, cpu_s) into the counts."""
        self._ring()
        out = self._proc.stdout.fileno()
        while True:
            answer = self._next_line()
            if answer is not None:
                break
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([out], [], [], min(left, 0.5))[0]:
                if left <= 0:
                    self._give_up("the writer did not drain its queue in time")
                    return
                continue
            if not self._read_writer():
                self._give_up("the writer process ended early")
                return
        self.messages = int(answer["messages"])
        self._dropped_writer_side = int(answer["dropped"])
        self.writer_cpu_s = float(answer["cpu_s"])
        if answer.get("error"):
            self.error = self.error or str(answer["error"])

    def _count_dropped(self, item: tuple) -> None:
        self.dropped_items += 1
        self._dropped_tick_side += message_count(item, self._image_period_s is not None)

    def _give_up(self, reason: str) -> None:
        """No more writing: note why, count everything still queued as dropped."""
        if self._gone:
            return
        self._gone = True
        self.error = self.error or reason
        for _, items in self._pending:
            for item in items:
                self._count_dropped(item)
        for item in self._batch_items:
            self._count_dropped(item)
        self._pending.clear()
        self._pending_items = 0
        self._batch_items = []
        self._close_pipe()

    def _ring(self) -> None:
        """Wake the writer now rather than at its next look at the pipe."""
        if self._doorbell is not None:
            try:
                os.write(self._doorbell, b"!")
            except OSError:
                pass  # full (it is ringing already) or the writer is gone

    def _close_pipe(self) -> None:
        if self._proc is not None and self._proc.stdin is not None and not self._proc.stdin.closed:
            try:
                self._proc.stdin.close()
            except OSError:
                pass
        self._fd = None
        if self._doorbell is not None:
            os.close(self._doorbell)
            self._doorbell = None



def _used_only(readings: list, tags: tuple, skip: frozenset) -> tuple[list, tuple]:
    """``readings`` without those of a type in ``skip``, and the (base tagged, tags) that go with what is left."""
    polls = tags[1]
    if polls and sum(k for _, k in polls) == len(readings):
        # Every reading's poll is known (each tick, when the base is tagged): keep poll by poll.
        kept: list = []
        runs: list[tuple[str, int]] = []
        i = 0
        for name, k in polls:
            part = [r for r in readings[i:i + k] if r.__class__ not in skip]
            i += k
            if part:
                kept += part
                if runs and runs[-1][0] == name:
                    runs[-1] = (name, runs[-1][1] + len(part))
                else:
                    runs.append((name, len(part)))
        return kept, (True, tuple(runs))
    sources = reading_sources(tags[0], polls, len(readings))
    kept = [(r, src) for r, src in zip(readings, sources or [None] * len(readings)) if r.__class__ not in skip]
    if sources is None:
        return [r for r, _ in kept], (tags[0], ())  # sources unknown before, unknown still
    runs: list[list] = []
    for _, src in kept:
        if runs and runs[-1][0] == src:
            runs[-1][1] += 1
        else:
            runs.append([src, 1])
    # Every kept reading's source is now told, the base's too (as if its poll had been tagged).
    return [r for r, _ in kept], (True, tuple((name, k) for name, k in runs))


def _record_servo_commands(run: Any, rec: McapRecorder) -> None:
    """Record every servo command the run sends (wrapping ``run.send_servo``, not the adapters, which
    other parts wrap for their own reasons: the watchdog's lock)."""
    send = run.send_servo

    def send_servo(cmd: ServoCommand, now_s: float) -> None:
        send(cmd, now_s)
        rec.on_servo(cmd, now_s)

    run.send_servo = send_servo


# -- what goes in the file besides the messages ---------------------------------------------------


def tree_nodes(run: Any) -> list[dict]:
    """The run's tree as a list, parents first: ``{id, name, kind, parent}`` per node.

    ``id`` is the node's stable id (its path from the root, the id the /tree
    channel's changes carry), ``kind`` what sort of node it is (``sequence``,
    ``action``...: :func:`beastbt.run.tree_ids.kind_of`), ``parent`` its
    parent's id (None for the root). Recordings made before the ids list
    ``{name, kind, depth, leaf}`` instead (kind then the class name).
    """
    return [n.as_dict() for n in run.layout]


def _file_text(path: Optional[str], data: Any) -> Optional[str]:
    """The text of ``path`` when it still parses to ``data`` (what was run), else ``data`` as YAML."""
    if path:
        from beastbt.core.file_refs import YAML_FILE, RefusedFile, read_capped
        try:
            text = read_capped(path, YAML_FILE).decode("utf-8")  # a regular file within the YAML cap, or none
            if data is None or yaml.safe_load(text) == data:
                return text
        except (RefusedFile, UnicodeDecodeError, yaml.YAMLError):
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
        "tree": json.dumps(tree_nodes(run)),
        "start_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "max_time_s": "" if opts.max_time_s is None else repr(opts.max_time_s),
        "answers": json.dumps(dict(opts.answers or {})),  # --answer: replay gives the questions the same
    }
    # For the Foxglove views the writer builds: the frame names and where the camera sits on base_link.
    from beastbt.robot.profile import section_config  # here: jsonschema, OpenCV only for a run being recorded
    info["frames"] = json.dumps(dataclasses.asdict(section_config(profile, "frames", FramesConfig)))
    camera = profile.section("camera")
    if camera is not None:
        from beastbt.devices.camera import CameraConfig
        from beastbt.vision.line_detector import LineDetectorConfig
        info["camera_mounting"] = json.dumps(dataclasses.asdict(CameraConfig.from_dict(camera).mounting))
        info["line_lookahead_m"] = repr(section_config(profile, "line_detector", LineDetectorConfig).lookahead_m)
    if profile.section("lidar") is not None:
        from beastbt.actuation.collision_monitor import footprint_radius
        from beastbt.devices.lidar_scan import LidarConfig
        info["footprint_radius_m"] = repr(footprint_radius(profile.data))  # the report's clearance from the scans
        info["lidar_mounting"] = json.dumps(dataclasses.asdict(section_config(profile, "lidar", LidarConfig).mounting))
    if run.io.magnetic_declination_deg is not None:
        info["magnetic_declination_deg"] = repr(run.io.magnetic_declination_deg)
    if world is not None:
        info["world_start"] = json.dumps([world.start_x, world.start_y, world.start_yaw])
        info["world_datum"] = json.dumps([world.frame.lat0_deg, world.frame.lon0_deg, world.frame.alt0_m])
        info["world_walls"] = json.dumps([list(_wall_tuple(w)) for w in world.walls])
        from beastbt.sim.obstacles import obstacle_outline
        info["world_obstacles"] = json.dumps([obstacle_outline(o) for o in world.obstacles])
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


# -- installation: into a prepared run, and its summary ------------------------------------------------

def recorder_of(run: Any) -> Optional[McapRecorder]:
    """The recorder attached to a :class:`~beastbt.run.runner.MissionRun`, if it records."""
    rec = getattr(run, "recorder", None)
    return rec if isinstance(rec, McapRecorder) else None


def config_from_options(opts: Any) -> RecordingConfig:
    """The recording config of a run: ``RunOptions.recording`` (a mapping) and ``record_images_hz`` (Hz)."""
    cfg = dict(opts.recording or {})
    hz = opts.record_images_hz
    if hz is not None:
        cfg["image_rate_hz"] = float(hz)
    return RecordingConfig.from_dict(cfg)


def images_asked(opts: Any) -> bool:
    """Whether the run asked for camera images for their own sake (``--record-images``, ``--record-sensors``, or
    ``image_rate_hz`` in ``RunOptions.recording``): then the camera runs for the recording even when nothing
    else looks through it."""
    return (opts.record_images_hz is not None or bool(getattr(opts, "record_sensors", False))
            or "image_rate_hz" in (opts.recording or {}))


def install(prepared: Any, live: Optional[tuple[str, int]] = None) -> Optional[McapRecorder]:
    """Attach a recorder to the run when it records (run folder and/or ``--record FILE``) or serves Foxglove
    live on ``live`` (host, port; ``--foxglove``), through the same writer process."""
    opts = prepared.options
    paths: list[Path] = []
    if prepared.folder is not None:
        paths.append(Path(prepared.folder.path) / "run.mcap")
    if opts.record_path:
        target = Path(opts.record_path)
        if not paths or target.resolve() != paths[0].resolve():
            paths.append(target)
    if not paths and live is None:
        return None
    config = config_from_options(opts)
    if prepared.folder is not None and "floor_free_mb" not in (opts.recording or {}):
        from beastbt.run.retention import RunsPolicy  # the runs folder's floor (profile runs:) holds for its recording
        config.floor_free_mb = RunsPolicy.from_section(prepared.profile.section("runs")).min_free_mb
    block = config.overflow == "block" or (config.overflow == "auto" and isinstance(prepared.clock, SimClock))
    info, attachments = run_info(prepared)
    rec = McapRecorder(paths, config, block_when_full=block, info=info, attachments=attachments, live=live)
    run = prepared.run
    camera = run.io.camera
    if camera is not None and config.image_rate_hz > 0 and images_asked(opts):
        # --record-images is frames kept per second, whatever the mission does: the camera runs for the
        # recording too (a mission that never looks at it would otherwise leave it off, and record none),
        # at that rate when nothing else needs more (a simulated camera renders only the frames kept), and
        # without the line detector when nothing reads lines (no line observations nobody asked for).
        # Without it (nor --record-sensors), only the frames the run takes anyway are kept: a recording
        # wakes no camera.
        camera.enable("recording", max_rate_hz=config.image_rate_hz, lines=False)
    # Events from before this hook (device warnings while the robot was assembled) go first.
    for ev in list(run.events.events):
        rec.on_event(ev)
    geometry = prepared.profile.section("geometry") or {}
    rec.on_scene(scene_description(prepared.mission, prepared.world, geometry.get("footprint_radius_m")),
                 prepared.clock.now())
    run.recorders.append(rec.on_tick)
    run.events.listeners.append(rec.on_event)
    inputs = getattr(run, "inputs", None)
    if inputs is not None:
        inputs.listeners.append(rec.on_input)
    _record_servo_commands(run, rec)
    if run.ctx.services.vision is not None:  # the mission asks the camera: its detectors' answers, for replay
        from beastbt.vision.recorded_answers import AnswerTap
        rec.vision_answers = AnswerTap.attach(run.ctx.services.vision)
    save = run.ctx.services.save_snapshot
    if save is not None:
        def save_and_record(name: str, frame: Any) -> str:
            path = save(name, frame)
            rec.on_snapshot(path, getattr(frame, "stamp_s", 0.0))
            return path

        run.ctx.services.save_snapshot = save_and_record
    if not opts.record_sensors:
        rec.keep_only_used(getattr(prepared, "reads", None))
    rec.tag_sources(run.io)
    rec.run = run
    rec.launch()  # the writer process imports while the rest of the run gets ready
    run.recorder = rec
    if paths:  # served live only: nothing recorded to count in the summary
        run.summary_contributors.append(contribute_summary)
    prepared.closers.append(rec.stop)
    if prepared.folder is not None:
        prepared.folder.finishers.append(rec.finish)
    else:
        prepared.closers.append(rec.finish)
    return rec


def contribute_summary(run: Any, summary: dict) -> None:
    """The summary's ``recording: {messages, dropped}`` (no path: the summary stays the same run to run)."""
    rec = recorder_of(run)
    if rec is None:
        return
    entry: dict = {"messages": rec.messages, "dropped": rec.dropped}
    if rec.error:
        entry["error"] = rec.error
    summary["recording"] = entry


__all__ = ["RecordingConfig", "McapRecorder", "install", "recorder_of", "contribute_summary", "run_info",
           "tree_nodes", "ns", "compression_type", "RECORDING_FORMAT", "MCAP_PROFILE",
           "TRUTH_FIELDS", "WATCHED_DEVICE_FLAGS"]
