"""The recording's writer process: items from the tick loop in, ``run.mcap`` out.

:class:`~beastbt.recording.recorder.McapRecorder` starts this module as a
separate process (``python -m beastbt.recording.writer``) and feeds
it items through a pipe (:mod:`beastbt.recording.wire`) on its
standard input. Everything that costs CPU happens here, on another core and
under another interpreter lock than the tick loop's: the readings become
JSON messages on the channels of :mod:`beastbt.recording.schemas`,
camera frames become JPEGs, and the ``mcap`` library writes compressed
chunks, one closed every ``chunk_interval_s`` of recorded clock time. Each
closed chunk goes to the file in one write, followed by a valid end (a
DataEnd record, a footer with no summary section, the magic) that the next
one overwrites: a run killed hard (a power cut, SIGKILL of everything) leaves
a valid MCAP file, read by ``mcap``'s own readers up to its last complete
chunk (``beastbt recover`` rebuilds one whose last write was torn). A file
that cannot be written (a full disk) is set back to its last valid end and
left; the run is told at once (a ``{"notice": text}`` line on standard
output) and goes on: the messages still go to Foxglove live.

Control items on the same pipe: ``("open", paths, config, info,
attachments)`` first; ``("stop",)`` asks for the counts so far (one JSON line
on standard output: messages, dropped, error, cpu_s) once everything before
it is written; ``("finish", summary_json)`` stores the run summary, closes
the file, answers once more and ends the process. When the pipe ends without
``finish`` (the run's process died), the file is still closed properly, with
metadata ``beastbt.cut`` saying so. The process ignores SIGINT and SIGTERM:
Ctrl-C stops the run, and the run, not the signal, ends its recording.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import os
import select
import signal
import sys
import time
from pathlib import Path
from typing import Any, Callable, NoReturn, Optional

import numpy as np
import orjson

from beastbt.blackboard.types import (BatteryState, FusedPose, GpsFix, ImuSample, JoystickState, LaserScan,
                                      LineObservation, VelocityCommand, WheelOdometry)
from beastbt.recording import foxglove as fx
from beastbt.recording import schemas as rs
from beastbt.recording.config import FramesConfig, RecordingConfig, compression_type
from beastbt.recording.foxglove import fox_time
from beastbt.recording.foxglove_live import LiveServer, start_live
from beastbt.recording.mcap_file import (COMMIT_MAX_BYTES, NoFile, RecordStream, describe_write_error,
                                         mcap_writer_class)
from beastbt.recording import detection_views as dv
from beastbt.recording import obstacle_views as ov
from beastbt.recording.scene import SceneView
from beastbt.recording.schemas import OFFSET_KEY
from beastbt.recording.wire import Frame, ItemDecoder, read_frames

RECORDING_FORMAT = "beastbt-run/1"
"""Written in the ``beastbt.run`` metadata; bumped when the channels change incompatibly."""

MCAP_PROFILE = "beastbt"

TRUTH_FIELDS = ("t_s", "x", "y", "yaw", "v_mps", "w_rps", "left_m", "right_m", "pan_rad", "tilt_rad", "battery_v")
"""The fields of a /truth message, in the order the tick side packs them."""


# -- conversions -------------------------------------------------------------------------------------


def ns(t_s: float) -> int:
    """Clock seconds to integer nanoseconds of the clock (never negative)."""
    return max(0, int(round(t_s * 1e9)))


def json_default(o: Any) -> Any:
    """numpy scalars and arrays, tuples of them: what the JSON encoder does not know."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"cannot record a {type(o).__name__}")


_ORJSON_OPTIONS = orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS
_dumps = orjson.dumps


def encode_json(obj: Any) -> bytes:
    """A message as compact JSON (UTF-8 bytes), by orjson: several times faster than :mod:`json` on the
    floats of a LiDAR scan, and the writer's main cost. NaN and infinity, which JSON (and Foxglove) do not
    know, become null; floats are written shortest-exact, so they read back to the same values."""
    return orjson.dumps(obj, default=json_default, option=_ORJSON_OPTIONS)


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


# -- the writer -----------------------------------------------------------------------------------------

class RunFileWriter:
    """Writes the items of one run into MCAP file(s) (the same bytes to each path), and to Foxglove live.

    ``live``: a :class:`~beastbt.recording.foxglove_live.LiveServer` that gets
    every message too; with no ``paths`` the run is only served live.

    ``messages`` counts the messages written; ``dropped`` the messages an
    item would have made when writing it failed; ``error`` is the first
    error, or None.
    """

    def __init__(self, paths: list[Path], config: RecordingConfig, info: dict,
                 attachments: list[tuple[str, str, bytes]], live: Optional[LiveServer] = None) -> None:
        Writer = mcap_writer_class()
        self.config = config
        self.messages = 0
        self.dropped = 0
        self.error: Optional[str] = None
        self.notices: list[str] = []
        """What the run must be told at once (a file that stopped being written: a full disk), not yet sent."""
        self._flushed_messages = 0
        """Messages in the files as of their last flush (what a failed flush leaves in them)."""
        self._images = config.image_rate_hz > 0
        self._channels: dict[str, int] = {}
        self._schema_ids: dict[str, int] = {}
        self._last_flush_s: Optional[float] = None
        self._offset_ns = int(info.get(OFFSET_KEY, 0) or 0)
        self.frames = FramesConfig.from_dict(json.loads(info["frames"]) if info.get("frames") else None)
        mounting = json.loads(info["camera_mounting"]) if info.get("camera_mounting") else None
        self._mount = fx.camera_mount(mounting)
        self._mounting = mounting
        """The profile's camera mounting (metres, degrees): the camera's geometry for calibration and annotations."""
        self._lookahead_m = float(info.get("line_lookahead_m") or 0.0)
        self._lidar: Optional[dict] = json.loads(info["lidar_mounting"]) if info.get("lidar_mounting") else None
        """The profile's LiDAR mounting on base_link (metres, degrees): base_link -> lidar on /tf."""
        self._geometries: dict[tuple[int, int], Any] = {}
        self._frame_log_ns: dict[int, int] = {}
        """Camera frame seq -> log time (ns) of its /sensors/camera message, for the newest 64 frames."""
        self._epochs = fx.EpochFixes()
        self._gps_altitude_m = 0.0
        self._gps_up_variance_m2 = 0.0
        """Altitude (m) and vertical variance (m^2) of the latest GPS fix: the planar EKF's /gps/fused uses them."""
        self._scene: Optional[SceneView] = None
        """What the run happens in (a ``scene`` item): /route once, /scene at the start and when map moves."""
        self._persons: list = []
        """The simulator's persons as last sampled ([x, y, radius], world metres): redrawn with /scene."""
        self._latched_views: dict[str, bytes] = {}
        """The last message of each obstacle view sent only on change (the zones): a client that subscribes late
        gets it again, live only."""
        self._servo_rad: dict[str, float] = {}
        """Last commanded angle of each servo by name (rad): the gimbal's pan and tilt move camera_link."""
        self._pose_odom: Optional[FusedPose] = None
        """The last tick's odometry pose (for the map -> odom of a pose on a saved map)."""
        self._map_from_odom: Optional[tuple[float, float, float]] = None
        """On a saved map: the localiser's map -> odom (x m, y m, yaw rad) for /tf, from the latest /map/pose."""
        self._live = live
        self._stream: Any = (RecordStream([Path(p) for p in paths], int(config.floor_free_mb * 1e6)) if paths
                             else NoFile())
        w: Any = (Writer(self._stream, chunk_size=config.chunk_max_bytes,
                         compression=compression_type(config.compression)) if paths else NoFile())
        w.start(profile=MCAP_PROFILE, library=f"beastbt ({RECORDING_FORMAT})")
        w.add_metadata("beastbt.run", {str(k): str(v) for k, v in info.items()})
        for name, media, data in attachments:
            w.add_attachment(create_time=0, log_time=0, name=name, media_type=media, data=data)
        self._writer = w
        # Every channel is declared up front (in a fixed order, so ids are the same run to run), even
        # those with no messages in this run: the file lists what a run of beastbt records.
        for topic in rs.CHANNELS:
            self._channel(topic)

    def write(self, item: tuple) -> None:
        """Write one item (a tick, an event, a device flag, a snapshot, a servo command); errors are counted."""
        if not self._stream.writing and self._live is None:
            self.dropped += message_count(item, self._images)  # nowhere to go: not even encoded
            return
        try:
            self._write_item(item)
        except Exception as exc:
            self.error = self.error or f"writing {item[0]}: {exc!r}"
            self.dropped += 1
        if self._stream.pending_bytes > COMMIT_MAX_BYTES:
            self.flush()  # many images between two chunk intervals: write them now rather than hold them

    def flush(self) -> None:
        """Close the current chunk and hand everything to the OS (each file then ends validly)."""
        self._writer.flush()
        self._check_files()

    def finish(self, metadata: Optional[dict[str, dict[str, str]]] = None) -> None:
        """Add ``metadata`` records (name -> strings), write the MCAP summary section and footer, close."""
        try:
            for name, values in (metadata or {}).items():
                self._writer.add_metadata(name, values)
            self._writer.finish()
        finally:
            self._stream.close()
            self._check_files()
            if self._live is not None:
                self._live.close()

    def _check_files(self) -> None:
        """After a flush: a file that could not be written is given up on; say so (a notice for the run)."""
        failures = self._stream.take_failures()
        if not failures:
            if self._stream.writing:
                self._flushed_messages = self.messages
            return
        if not self._stream.writing:
            # What the failed flush held is not in any file: count it as dropped, from now on everything is.
            self.dropped += self.messages - self._flushed_messages
            self.messages = self._flushed_messages
        still = [str(p) for p in getattr(self._stream, "paths", [])]
        for path, exc in failures:
            text = (f"stopped: {describe_write_error(path, exc)}; {path.name} keeps its {self._flushed_messages} "
                    f"messages up to its last chunk; " + (f"still recording to {', '.join(still)}; " if still else "")
                    + "the mission goes on")
            self.error = self.error or text
            self.notices.append(text)
        if self._stream.writing:
            self._flushed_messages = self.messages  # the files still written took this flush

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
            if self._live is not None:
                self._live.add_channel(topic, name, rs.schema_bytes(schema))
        return cid

    def _ns(self, t_s: float) -> int:
        """Clock seconds to log time: Unix epoch nanoseconds (see OFFSET_KEY)."""
        return self._offset_ns + ns(t_s)

    def _emit(self, topic: str, t_ns: int, obj: dict) -> None:
        cid = self._channels.get(topic)
        if cid is None:
            cid = self._channel(topic)
        if self._stream.writing:
            self.messages += 1
        else:
            self.dropped += 1  # served live only: no file takes it any more
        data = _dumps(obj, default=json_default, option=_ORJSON_OPTIONS)  # encode_json, a call less (per message)
        self._writer.add_message(cid, t_ns, data, t_ns, self.messages)  # (channel, log time, data, publish time, seq)
        if self._live is not None:
            self._live.log(topic, data, t_ns)  # the same bytes and time, to Foxglove live

    def _write_item(self, item: tuple) -> None:
        kind = item[0]
        if kind == "tick":
            self._write_tick(item)
        elif kind == "event":
            _, time_s, ev_kind, text = item
            t = self._ns(time_s)
            ev = {"time_s": time_s, "kind": ev_kind, "text": text}
            self._emit("/events", t, ev)
            if ev_kind == "failsafe":
                self._emit("/failsafes", t, ev)
            self._emit("/log", t, {"timestamp": fox_time(t), "level": log_level(ev_kind),
                                   "message": f"{ev_kind}: {text}", "name": ev_kind, "file": "", "line": 0})
        elif kind == "flag":
            _, tick, now_s, key, attr, value = item
            self._emit("/devices/state", self._ns(now_s), {"tick": tick, "now_s": now_s, "device": key,
                                                           "field": attr, "value": value})
        elif kind == "input":
            _, tick, now_s, source, control, body = item
            self._emit("/operator/input", self._ns(now_s), {"tick": tick, "now_s": now_s, "source": source,
                                                            "control": control, "body": body})
        elif kind == "snapshot":
            _, stamp_s, path = item
            data = Path(path).read_bytes()
            self._writer.add_attachment(create_time=0, log_time=self._ns(stamp_s), name=Path(path).name,
                                        media_type="image/jpeg", data=data)
            # and as a message, so that Foxglove shows the photos on their own channel at their time
            self._emit("/camera/photo", self._ns(stamp_s), {"timestamp": fox_time(self._ns(stamp_s)),
                                                            "frame_id": self.frames.camera_optical,
                                                            "data": base64.b64encode(data).decode("ascii"),
                                                            "format": "jpeg"})
        elif kind == "vision_answers":
            from beastbt.vision.answer_messages import TOPIC, answer_message
            _, now_s, answers = item
            for a in answers:
                self._emit(TOPIC, self._ns(now_s), answer_message(a))
        elif kind == "scene":
            _, now_s, description = item
            t = self._ns(now_s)
            self._scene = SceneView(description, self.frames)
            self._emit("/route", t, self._scene.route_message())
            self._emit("/scene", t, self._scene.scene_message(t))
        elif kind == "views":
            _, now_s, views = item
            self._write_views(self._ns(now_s), views)
        elif kind == "detections":
            _, now_s, entries = item
            self._write_detections(self._ns(now_s), entries)
        elif kind == "servo":
            _, now_s, c = item
            if c.name is not None and c.angle_rad is not None:
                self._servo_rad[c.name] = c.angle_rad
            self._emit("/cmd/servo", self._ns(now_s), {"now_s": now_s, "name": c.name, "angle_rad": c.angle_rad,
                                                       "channel": c.channel, "pulse_s": c.pulse_s,
                                                       "stamp_s": c.stamp_s})

    def _write_tick(self, item: tuple) -> None:
        (_, tick, now_s, readings, pose_odom, pose, cmd_mission, cmd_mux, cmd_gate, mux_source, changed,
         truth, tags) = item
        sources = reading_sources(*tags, len(readings))
        t = self._ns(now_s)
        if self._live is not None and self._scene is not None and self._live.take_resend():
            # A client subscribed to /scene or /route after they went out: send them again, to it live only.
            self._live.log("/route", encode_json(self._scene.route_message()), t)
            self._live.log("/scene", encode_json(self._scene.scene_message(t)), t)
            for topic, data in self._latched_views.items():
                self._live.log(topic, data, t)
        emit = self._emit
        frames = self.frames
        fixes: list[GpsFix] = []
        image_at: Optional[tuple[float, tuple[int, int, int, int]]] = None
        """(stamp, (camera w, h, published w, h)) of the frame published on /camera/image this tick."""
        for i, r in enumerate(readings):
            source = sources[i] if sources is not None else None
            conv = _SENSOR_CONVERTERS.get(r.__class__)
            if conv is not None:
                d = conv[1](r)
                d["source"] = source
                emit(conv[0], t, d)
                if r.__class__ is GpsFix:
                    fixes.append(r)
            elif r.__class__ is LaserScan:
                emit("/scan", t, fx.laser_scan(t, r, source))  # the revolution goes only there (no /sensors copy)
            elif r.__class__ is Frame:
                self._frame_log_ns[r.seq] = t  # the detections of this frame are stamped like its image
                if len(self._frame_log_ns) > 64:
                    del self._frame_log_ns[next(iter(self._frame_log_ns))]
                emit("/sensors/camera", t, {"stamp_s": r.stamp_s, "seq": r.seq, "width": r.width,
                                            "height": r.height, "image_recorded": r.image is not None,
                                            "source": source})
                if r.image is not None:
                    published = self._write_image(r, t)
                    if published is not None:
                        image_at = (r.stamp_s, published)
            elif dataclasses.is_dataclass(r):
                name = type(r).__name__
                topic = rs.SENSOR_TOPICS.get(name, f"/sensors/{_snake(name)}")
                if topic not in self._channels:
                    self._channel(topic, {**rs.GENERIC_READING, "title": f"beastbt.{name}"})
                d = generic_dict(r)
                d.setdefault("source", source)
                emit(topic, t, d)
        if image_at is not None:
            self._describe_image(t, image_at[0], image_at[1], readings)
        if fixes:
            for fix in self._epochs.take(fixes):
                emit("/gps/fix", t, fx.location_fix(fix, t, frames.gps))
                if fix.alt_msl is not None:
                    self._gps_altitude_m = fix.alt_msl
                self._gps_up_variance_m2 = float(fix.covariance_enu[2][2])
        if pose is not None:
            emit("/estimate/fused", t, pose_dict(pose))
            emit("/pose/fused", t, fx.pose_in_frame(pose, t, frames.map))
            fused = fx.fused_location_fix(pose, t, frames.base_link, self._gps_altitude_m, self._gps_up_variance_m2)
            if fused is not None:
                emit("/gps/fused", t, fused)
            scene = self._scene
            if scene is not None and scene.on_pose(pose.x, pose.y, pose.lat, pose.lon, pose.position_valid):
                emit("/scene", t, scene.scene_message(t))  # the map frame found its place on Earth: redraw
                if self._persons:  # and the persons with it, where they stand (they are sent only as they move)
                    emit("/sim/persons", t, ov.persons_update(t, frames.map, self._persons, scene.world_point))
        if pose_odom is not None:
            emit("/estimate/odom", t, pose_dict(pose_odom))
            emit("/odom", t, fx.odometry(t, frames, pose_odom))
        if pose is not None or pose_odom is not None:
            servo = self._servo_rad
            emit("/tf", t, fx.frame_transforms(t, frames, pose, pose_odom, self._mount, servo.get("pan", 0.0),
                                               servo.get("tilt", 0.0), self._lidar, self._map_from_odom))
        if pose_odom is not None:
            self._pose_odom = pose_odom
        if cmd_mission is not None:
            emit("/cmd/mission", t, stage_dict(tick, now_s, cmd_mission, mux_source))
        if mux_source == "teleop":
            emit("/cmd/teleop", t, stage_dict(tick, now_s, cmd_mux, mux_source))
        emit("/cmd/mux", t, stage_dict(tick, now_s, cmd_mux, mux_source))
        emit("/cmd/gate", t, stage_dict(tick, now_s, cmd_gate, mux_source))
        if changed:
            emit("/tree", t, {"tick": tick, "now_s": now_s,
                              "changes": [{"id": i, "name": n, "status": s, "feedback": f or ""}
                                          for n, s, f, i in changed]})
        if truth is not None:
            emit("/truth", t, dict(zip(TRUTH_FIELDS, truth)))
        last = self._last_flush_s
        if last is None:
            self._last_flush_s = now_s
        elif now_s - last >= self.config.chunk_interval_s - 1e-9:
            # Close the chunk and hand it to the OS: a hard kill now loses at most one interval.
            self.flush()
            self._last_flush_s = now_s

    def _write_views(self, t: int, views: dict) -> None:
        """The obstacle views that changed (:class:`~beastbt.recording.obstacle_views.ObstacleSampler`): /costmap,
        /local_plan, /collision_monitor/zones, /map, /path, /global_costmap, /plan, /map/pose, /sim/persons,
        /sim/contact, /localisation/particles and /localisation/quality."""
        frames = self.frames
        if "costmap" in views:
            self._emit("/costmap", t, ov.costmap_grid(t, frames.odom, views["costmap"]))
        if "plan" in views:
            self._emit("/local_plan", t, ov.plan_update(t, frames.odom, views["plan"]))
        if "zones" in views:
            msg = ov.zones_update(t, frames.base_link, views["zones"])
            self._emit("/collision_monitor/zones", t, msg)
            self._latched_views["/collision_monitor/zones"] = encode_json(msg)  # sent once: a late client needs it
        if "map" in views:  # latched: a client that joins later gets the map at once
            from beastbt.recording.map_views import map_grid
            msg = map_grid(t, frames.map, *views["map"])
            self._emit("/map", t, msg)
            self._latched_views["/map"] = encode_json(msg)
        if "path" in views:
            from beastbt.recording.map_views import path_update
            self._emit("/path", t, path_update(t, frames.map, views["path"]))
        if "global_costmap" in views:  # latched: sent only when it changed
            from beastbt.recording.global_views import global_costmap_grid
            marks = views["global_costmap"]
            msg = global_costmap_grid(t, frames.map if marks.frame == "map" else frames.odom, marks)
            self._emit("/global_costmap", t, msg)
            self._latched_views["/global_costmap"] = encode_json(msg)
        if "gps_plan" in views:  # the way round a GPS go_to follows, each time it changes (odom)
            from beastbt.recording.global_views import gps_plan
            from beastbt.recording.map_views import path_update
            msg = path_update(t, frames.odom, gps_plan(views["gps_plan"]))
            self._emit("/plan", t, msg)
            self._latched_views["/plan"] = encode_json(msg)
        if "map_pose" in views:
            from beastbt.recording.map_views import map_pose_message
            self._emit("/map/pose", t, map_pose_message(t, frames.map, views["map_pose"]))
            if self._pose_odom is not None:  # the views come after their tick: that tick's odometry pose
                x, y, yaw = views["map_pose"][:3]
                on_map = FusedPose(self._pose_odom.stamp_s, x, y, yaw)
                self._map_from_odom = fx.map_to_odom(on_map, self._pose_odom)
        contact = views.get("contact")
        if contact is not None:
            self._emit("/sim/contact", t, ov.contact_message(contact))
            scene = self._scene
            self._persons = contact["persons"]
            if contact["moved"] and contact["persons"] and scene is not None:
                self._emit("/sim/persons", t, ov.persons_update(t, frames.map, contact["persons"], scene.world_point))
        localisation = views.get("localisation")
        if localisation is not None:
            self._emit("/localisation/particles", t, ov.particles_update(t, frames.map, localisation))
            self._emit("/localisation/quality", t, ov.quality_message(localisation))

    def _write_detections(self, now_ns: int, entries: list) -> None:
        """/camera/detections and /camera/tags of each frame entry (:mod:`beastbt.recording.detection_views`),
        stamped with the log time of that frame's /sensors/camera message (its /camera/image's, when it has one);
        an entry with no frame (seq -1: the detectors sleep) clears the image's annotations at ``now_ns``."""
        for entry in entries:
            t = self._frame_log_ns.get(entry["seq"], now_ns)
            scale = dv.published_scale(entry["size"][0], self.config.image_max_width_px)
            self._emit("/camera/detections", t, dv.image_annotations(t, entry, scale))
            tags = dv.tags_update(t, self.frames.base_link, entry)
            if tags is not None:
                self._emit("/camera/tags", t, tags)

    def _write_image(self, frame: Frame, t_ns: int) -> Optional[tuple[int, int, int, int]]:
        """Publish a frame on /camera/image (JPEG, scaled down to ``image_max_width_px``); returns (camera width,
        height, published width, height) in pixels, or None when it could not be encoded."""
        import cv2  # only runs with a camera need it
        image = frame.image
        max_w = self.config.image_max_width_px
        data: Optional[bytes] = None
        if max_w and frame.width > max_w:
            h = max(1, int(round(frame.height * max_w / frame.width)))
            image = cv2.resize(image, (max_w, h), interpolation=cv2.INTER_AREA)
        elif frame.jpeg is not None:
            data = frame.jpeg  # the camera's own JPEG, at a size that needs no scaling: recorded as it came
        if data is None:
            ok, jpeg = cv2.imencode(".jpg", image, [int(cv2.IMWRITE_JPEG_QUALITY), self.config.image_jpeg_quality])
            if not ok:
                self.dropped += 1
                return None
            data = jpeg.tobytes()
        self._emit("/camera/image", t_ns, {"timestamp": fox_time(t_ns), "frame_id": self.frames.camera_optical,
                                           "data": base64.b64encode(data).decode("ascii"),
                                           "format": "jpeg"})
        return frame.width, frame.height, int(image.shape[1]), int(image.shape[0])

    def _describe_image(self, t_ns: int, stamp_s: float, sizes: tuple[int, int, int, int], readings: list) -> None:
        """/camera/calibration and /camera/annotations of the image just published (same timestamp: Foxglove's
        image panel pairs them by it). Annotations only when the detector looked at that frame."""
        if not self._mounting:
            return
        geometry = self._geometry(*sizes)
        self._emit("/camera/calibration", t_ns, fx.camera_calibration(t_ns, self.frames.camera_optical, geometry))
        for r in readings:
            if r.__class__ is LineObservation and r.stamp_s == stamp_s:
                self._emit("/camera/annotations", t_ns, fx.line_annotations(t_ns, r, geometry, self._lookahead_m))
                break

    def _geometry(self, width: int, height: int, out_w: int, out_h: int) -> Any:
        """The camera as the line detector sees it (mounting, gimbal at 0), at the published image size."""
        key = (width, height, out_w, out_h)
        geometry = self._geometries.get(key)
        if geometry is None:
            from beastbt.vision.camera_model import CameraGeometry
            m = self._mounting
            geometry = CameraGeometry(width_px=width, height_px=height, hfov_deg=m["hfov_deg"], height_m=m["height_m"],
                                      pitch_deg=m["pitch_deg"], x_offset_m=m["x_offset_m"]).scaled_to(out_w, out_h)
            self._geometries[key] = geometry
        return geometry


def reading_sources(base_tagged: bool, tags: tuple, n: int) -> Optional[list]:
    """Each of a tick's ``n`` readings' source (the device poll it came from), or None when they do not add up.

    ``tags``: ``(device, readings it returned)`` in the order the loop polled;
    ``base_tagged``: the base's poll is among them (when it is not, the
    readings the tags do not account for are the base's: it polls first).
    """
    if not tags:
        return None
    counted = sum(k for _, k in tags)
    if counted != n:
        if base_tagged or tags[0][0] == "base" or counted > n:
            return None
        tags = (("base", n - counted),) + tuple(tags)
    out: list = []
    for name, k in tags:
        out.extend([name] * k)
    return out


def message_count(item: tuple, images: bool) -> int:
    """How many messages an item would make (for counting what was dropped); ``images``: frames are recorded."""
    kind = item[0]
    if kind == "event":
        return 3 if item[2] == "failsafe" else 2
    if kind in ("servo", "flag", "snapshot", "input"):
        return 1
    if kind == "vision_answers":
        return len(item[2])
    if kind == "scene":
        return 2  # /route, /scene
    if kind == "detections":
        # /camera/detections for each entry, and /camera/tags for those with a tag placed in the base frame
        return sum(1 + any(t["position_m"] is not None and t["facing_rad"] is not None for t in e.get("tags", ()))
                   for e in item[2])
    if kind == "views":
        views = item[2]
        contact = views.get("contact")
        return (("costmap" in views) + ("plan" in views) + ("zones" in views) + ("map" in views) + ("path" in views)
                + ("map_pose" in views) + 2 * ("localisation" in views) + ("global_costmap" in views)
                + ("gps_plan" in views)
                + (0 if contact is None else 1 + bool(contact["moved"] and contact["persons"])))
    if kind != "tick":
        return 0
    (_, _tick, _now, readings, pose_odom, pose, cmd_mission, _mux, _gate, mux_source, changed, truth, _src) = item
    n = 2  # mux, gate
    epochs = set()
    for r in readings:
        # A published image: /sensors/camera, /camera/image, and at most its calibration and annotations.
        n += 4 if (r.__class__ is Frame and r.image is not None) else 1
        if r.__class__ is GpsFix:
            epochs.add(r.time_utc)  # /gps/fix: one per epoch (at most: one may have gone out already)
    n += len(epochs)
    n += 2 * (pose is not None) + 2 * (pose_odom is not None) + (cmd_mission is not None)
    n += (pose is not None and pose.position_valid and pose.lat is not None)  # /gps/fused
    n += (pose is not None or pose_odom is not None)  # /tf
    n += (mux_source == "teleop") + bool(changed) + (truth is not None)
    return n


# -- the process ----------------------------------------------------------------------------------------


CUT_REASON = "the run's process ended without finishing its recording (killed, or it crashed)"
"""The ``reason`` of metadata ``beastbt.cut``."""


def _send_notices(writer: RunFileWriter, reply: Callable[[dict], None]) -> None:
    """Send the writer's notices, unasked: the run reads them between ticks and makes each an event."""
    for text in writer.notices:
        reply({"notice": text})
    writer.notices.clear()


def serve(read: Callable[[int], bytes], reply: Callable[[dict], None]) -> int:
    """The writer process's loop: items from ``read`` (``b''`` at the end), answers through ``reply``.

    Returns the process's exit code: 0, or 1 when the recording could not
    be written whole.
    """
    cpu0 = time.process_time()
    decoder = ItemDecoder()
    writer: Optional[RunFileWriter] = None
    state = {"dropped": 0, "error": None}

    def counts() -> dict:
        error = state["error"] or (writer.error if writer is not None else None)
        return {"messages": writer.messages if writer is not None else 0,
                "dropped": state["dropped"] + (writer.dropped if writer is not None else 0),
                "error": error, "cpu_s": time.process_time() - cpu0}

    images = True
    try:
        for item in read_frames(read, decoder):
            tag = item[0]
            if tag == "open":
                _, paths, config, info, attachments, *more = item
                live, live_error = start_live(more[0] if more else None)
                if live_error is not None:
                    # Said at once, on the run's terminal (the writer shares its standard error): the run goes on.
                    print(f"beastbt: {live_error}", file=sys.stderr, flush=True)
                try:
                    cfg = RecordingConfig.from_dict(config)
                    images = cfg.image_rate_hz > 0
                    writer = RunFileWriter(paths, cfg, info, attachments, live=live)
                except Exception as exc:
                    state["error"] = f"could not open the recording: {exc!r}"
                    if live is not None:
                        live.close()
            elif tag == "stop":
                if writer is not None:
                    try:
                        writer.flush()
                    except Exception as exc:
                        state["error"] = state["error"] or f"flushing: {exc!r}"
                    _send_notices(writer, reply)
                reply(counts())
            elif tag == "finish":
                summary_json = item[1]
                if writer is not None:
                    try:
                        writer.finish({"beastbt.summary": {"json": summary_json}} if summary_json else None)
                    except Exception as exc:
                        state["error"] = state["error"] or f"finishing the file: {exc!r}"
                    _send_notices(writer, reply)  # the end did not fit on the disk: the run still says it
                final = counts()
                reply(final)
                return 0 if final["error"] is None else 1
            elif writer is not None:
                writer.write(item)
            else:
                state["dropped"] += message_count(item, images)
            if writer is not None and writer.notices:
                _send_notices(writer, reply)
    except Exception as exc:  # a corrupt stream: keep what was written
        state["error"] = state["error"] or f"reading the run's items: {exc!r}"
    if writer is not None:
        # The pipe ended without "finish": the run's process is gone. Close the file properly anyway.
        try:
            writer.finish({"beastbt.cut": {"reason": CUT_REASON}})
        except Exception:
            return 1
    return 1


def _yield_to_the_loop() -> None:
    """Ask the OS to treat this process as batch work (Linux ``SCHED_BATCH``).

    A pipe write wakes its reader, and Linux may run a woken process at once
    on the writer's core, before the writer: the tick loop would then wait
    for a batch of JSON and MCAP work. A batch-class process never preempts
    on wakeup; it still gets its fair share of CPU, so the recording keeps up.
    """
    try:
        os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
    except (AttributeError, OSError):
        pass  # not Linux: the default policy still works


POLL_PERIOD_S = 0.1
"""How long the writer waits when the pipe is empty before it looks again (wall seconds). The run sends a batch
every ``send_interval_s`` (0.5 s) and rings the doorbell when it waits, so looking more often only costs: at
0.02 s the idle writer used 0.16 % of a core here, at 0.1 s 0.06 %."""

BUSY_POLL_S = 0.005
"""The wait instead while the run sends faster than :data:`BUSY_BYTES_PER_S` (a simulation at ``--speed max``):
the writer keeps pace, so that the end of the run finds little to catch up on (at 0.1 s, up to a tenth of a
second of a flat-out run's items, about 16 ms of writing that the run's end waited for) and the pipe does not
fill up in between."""

BUSY_BYTES_PER_S = 4e6
"""Bytes per wall second read from the pipe above which the writer polls every :data:`BUSY_POLL_S` (a patrol
at real time sends about 0.12 MB/s, with camera frames at 2 Hz about 2 MB/s; flat out, 20 MB/s)."""


def _polling_reader(fd: int, doorbell: Optional[int]) -> Callable[[int], bytes]:
    """``read(n)`` on ``fd`` that, while the pipe is empty, waits on ``doorbell`` for POLL_PERIOD_S at most
    (BUSY_POLL_S while the run sends fast).

    A reader blocked in the data pipe would be woken by each write, and on a
    virtual machine that wake-up (an interrupt to another core) costs the
    tick loop tens of microseconds per write. Here the data pipe never wakes
    anyone: the writer looks at it every POLL_PERIOD_S, and the run rings the
    doorbell (a second pipe) only when it waits for an answer.
    """
    os.set_blocking(fd, False)
    since = time.monotonic()
    got = 0
    wait = POLL_PERIOD_S

    def read(n: int) -> bytes:
        nonlocal doorbell, since, got, wait
        while True:
            try:
                data = os.read(fd, n)
            except BlockingIOError:
                data = None
            if data is not None:
                got += len(data)
                return data
            now = time.monotonic()
            if now - since >= POLL_PERIOD_S:  # how fast the run sends, over the last tenth of a second or more
                wait = BUSY_POLL_S if got >= BUSY_BYTES_PER_S * (now - since) else POLL_PERIOD_S
                since, got = now, 0
            if doorbell is None:
                time.sleep(wait)
            elif select.select([doorbell], [], [], wait)[0] and not os.read(doorbell, 4096):
                doorbell = None  # the run closed it: keep polling the data pipe until it ends

    return read


def main() -> NoReturn:
    """Entry point of the writer process: standard input in, answers on standard output."""
    # Ctrl-C and a polite kill go to the whole process group: the run handles them and then ends its
    # recording through the pipe; the writer must outlive the signal to write that end.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _yield_to_the_loop()
    fd_in = sys.stdin.fileno()
    doorbell = int(sys.argv[2]) if len(sys.argv) > 2 else None
    out = sys.stdout

    def reply(d: dict) -> None:
        try:
            out.write(json.dumps(d) + "\n")
            out.flush()
        except (BrokenPipeError, OSError):
            pass  # the run's process is gone: nobody to tell

    code = serve(_polling_reader(fd_in, doorbell), reply)
    # The file is closed and the run told: end now, without the interpreter's teardown (tens of ms the
    # run would otherwise wait for).
    os._exit(code)


if __name__ == "__main__":
    main()
