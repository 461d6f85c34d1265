"""The channels of a run recording (``run.mcap``) and the JSON Schema of each.

Every channel carries JSON messages (MCAP message encoding ``json``) described
by a JSON Schema (schema encoding ``jsonschema``). Where Foxglove has a
well-known schema (``foxglove.LaserScan``, ``foxglove.LocationFix``, ``foxglove.FrameTransforms``,
``foxglove.PoseInFrame``, ``foxglove.CompressedImage``, ``foxglove.Log``...)
the channel declares Foxglove's own schema (shipped in ``foxglove_schemas/``)
under that name, so a run opens in Foxglove with a map, a 3D view, the images
and a log panel. Everything else is a ``beastbt.*`` schema whose fields are exactly the
dataclass fields of :mod:`beastbt.blackboard.types` (SI units, ENU frames), so
that ``beastbt replay`` can rebuild the readings bit for bit.

Log time (and publish time) of every message = Unix epoch nanoseconds: the
run's clock plus the offset stored in the ``beastbt.run`` metadata
(:data:`OFFSET_KEY`): in the simulator the wall time at the first tick plus
the simulated time, on the robot the wall time. A Foxglove message's own
``timestamp`` equals its log time. Readers subtract the offset
(:func:`beastbt.recording.reader.read_recording`), so two runs with the same
seed give the same messages apart from those timestamps.

Messages are strict JSON: a value that is not a finite number (NaN from a
diverged estimate, infinity) is written as null, since JSON has no NaN and
Foxglove's parser rejects the token.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

OFFSET_KEY = "log_time_offset_ns"
"""``beastbt.run`` metadata: log time (Unix epoch ns) = clock time (ns) + this. The recorder sets it at the
run's first tick (wall time then, minus the clock's time then); a file without it logs clock time."""

# -- building blocks ---------------------------------------------------------------

_NUM = {"type": "number"}
_OPT_NUM = {"type": ["number", "null"]}
_OPT_INT = {"type": ["integer", "null"]}
_STAMP = {"type": "number", "description": "When the value was measured, clock seconds."}
_NOW = {"type": "number", "description": "Clock time of the tick that handled it, seconds."}
_TICK = {"type": "integer", "minimum": 0, "description": "Tick number, from 0."}
_VEC3 = {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3}
_MAT3 = {"type": "array", "items": _VEC3, "minItems": 3, "maxItems": 3}


_SOURCE = {"type": ["string", "null"],
           "description": "The device poll it came from: 'base' or the sensor's name (io.sensors); null if unknown."}


def _reading(title: str, description: str, props: dict) -> dict:
    """A sensor stream's schema: the reading's fields plus where it came from."""
    return _obj(title, description, {**props, "source": _SOURCE})


def _obj(title: str, description: str, props: dict, required: Any = None) -> dict:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title, "description": description, "type": "object",
        "properties": props, "required": list(props) if required is None else list(required),
        "additionalProperties": False,
    }


# -- Foxglove well-known schemas: Foxglove's own, unchanged (foxglove_schemas/, from @foxglove/schemas 2.1.0) --

FOXGLOVE_SCHEMAS_DIR = Path(__file__).resolve().parent / "foxglove_schemas"
"""Where the official JSON Schemas of the Foxglove types beastbt writes are shipped."""


def foxglove_schema(type_name: str) -> dict:
    """The official JSON Schema of ``foxglove.<type_name>`` (``LocationFix``...), as shipped with beastbt."""
    return json.loads((FOXGLOVE_SCHEMAS_DIR / f"{type_name}.json").read_text(encoding="utf-8"))


FOXGLOVE_LOCATION_FIX = foxglove_schema("LocationFix")
FOXGLOVE_POSE_IN_FRAME = foxglove_schema("PoseInFrame")
FOXGLOVE_COMPRESSED_IMAGE = foxglove_schema("CompressedImage")
FOXGLOVE_LOG = foxglove_schema("Log")
FOXGLOVE_FRAME_TRANSFORMS = foxglove_schema("FrameTransforms")
FOXGLOVE_ODOMETRY = foxglove_schema("Odometry")
FOXGLOVE_SCENE_UPDATE = foxglove_schema("SceneUpdate")
FOXGLOVE_GEOJSON = foxglove_schema("GeoJSON")
FOXGLOVE_CAMERA_CALIBRATION = foxglove_schema("CameraCalibration")
FOXGLOVE_IMAGE_ANNOTATIONS = foxglove_schema("ImageAnnotations")
FOXGLOVE_LASER_SCAN = foxglove_schema("LaserScan")
FOXGLOVE_GRID = foxglove_schema("Grid")

# -- beastbt schemas (exact dataclass fields) ------------------------------------------

GPS_FIX = _reading("beastbt.GpsFix", "GpsFix as the GPS driver produced it (degrees, metres, m^2).", {
    "stamp_s": _STAMP, "lat": _NUM, "lon": _NUM, "alt_msl": _OPT_NUM, "quality": {"type": "integer"},
    "sats": _OPT_INT, "hdop": _OPT_NUM, "speed_mps": _OPT_NUM, "track_deg": _OPT_NUM,
    "time_utc": {"type": ["string", "null"]}, "sentence": {"type": "string"}, "covariance_enu": _MAT3})

IMU_SAMPLE = _reading("beastbt.ImuSample", "ImuSample, body frame (rad/s, m/s^2, tesla, deg C).", {
    "stamp_s": _STAMP, "gyro_rps": _VEC3, "accel_mps2": _VEC3,
    "mag_t": {"oneOf": [_VEC3, {"type": "null"}]}, "temperature_c": _OPT_NUM})

WHEEL_ODOMETRY = _reading("beastbt.WheelOdometry", "Cumulative wheel travel (m) and wheel speeds (m/s).", {
    "stamp_s": _STAMP, "left_m": _NUM, "right_m": _NUM, "left_mps": _NUM, "right_mps": _NUM})

BATTERY_STATE = _reading("beastbt.BatteryState", "Battery voltage (V).", {"stamp_s": _STAMP, "voltage_v": _NUM})

JOYSTICK_STATE = _reading("beastbt.JoystickState", "Named joystick axes (-1..1) and buttons.", {
    "stamp_s": _STAMP, "axes": {"type": "object", "additionalProperties": _NUM},
    "buttons": {"type": "object", "additionalProperties": {"type": ["boolean", "integer"]}},
    "connected": {"type": "boolean"}})

LINE_OBSERVATION = _reading("beastbt.LineObservation", "What the line detector saw (body frame, m, rad).", {
    "stamp_s": _STAMP, "seen": {"type": "boolean"}, "offset_m": _NUM, "angle_rad": _NUM, "width_m": _NUM,
    "confidence": _NUM, "intersection": {"type": "boolean"}, "intersection_distance_m": _OPT_NUM,
    "line_end": {"type": "boolean"}})

CAMERA_FRAME_INFO = _reading("beastbt.CameraFrameInfo",
                         "One camera frame as it arrived (the pixels go to /camera/image at a reduced rate).", {
                             "stamp_s": _STAMP, "seq": {"type": "integer"}, "width": {"type": "integer"},
                             "height": {"type": "integer"},
                             "image_recorded": {"type": "boolean",
                                                "description": "True when this frame is also on /camera/image."}})

FUSED_POSE = _obj("beastbt.FusedPose", "An estimator output: local ENU metres, radians, m/s, rad/s.", {
    "stamp_s": _STAMP, "x": _NUM, "y": _NUM, "yaw": _NUM, "speed_mps": _NUM, "yaw_rate_rps": _NUM,
    "covariance": _MAT3, "distance_m": _NUM, "heading_valid": {"type": "boolean"},
    "position_valid": {"type": "boolean"}, "lat": _OPT_NUM, "lon": _OPT_NUM})

STAGE_COMMAND = _obj("beastbt.StageCommand",
                     "A body velocity command at one stage of mission -> mux -> gate (m/s, rad/s).", {
                         "tick": _TICK, "now_s": _NOW, "linear_mps": _NUM, "angular_rps": _NUM, "stamp_s": _NUM,
                         "source": {"type": "string", "description": "Who made the command (mission, teleop...)."},
                         "mux_source": {"type": "string", "description": "Which input the mux selected this tick."}})

SERVO_COMMAND = _obj("beastbt.ServoCommand", "A servo command the run sent to its servo adapters (rad, s).", {
    "now_s": _NOW, "name": {"type": ["string", "null"]}, "angle_rad": _OPT_NUM, "channel": _OPT_INT,
    "pulse_s": _OPT_NUM, "stamp_s": _NUM})

TREE_CHANGES = _obj("beastbt.TreeChanges", "The tree nodes whose status changed at one tick.", {
    "tick": _TICK, "now_s": _NOW,
    "changes": {"type": "array", "items": {
        "type": "object", "additionalProperties": False, "required": ["id", "name", "status", "feedback"],
        "properties": {"id": {"type": "string", "pattern": "^[0-9]+(\\.[0-9]+)*$",
                              "description": "The node's stable id, its path from the root ('0.1.2', as in the "
                                             "'tree' list of the beastbt.run metadata); a tree put in later "
                                             "(a return_home) counts from '1'. Steps that share a name differ "
                                             "by id."},
                       "name": {"type": "string"},
                       "status": {"enum": ["RUNNING", "SUCCESS", "FAILURE", "INVALID"]},
                       "feedback": {"type": "string"}}}}})

DEVICE_STATE = _obj("beastbt.DeviceState",
                    "A device state that parts of the run read besides its readings, when it changes.", {
                        "tick": _TICK, "now_s": _NOW,
                        "device": {"type": "string", "description": "The device's name on the robot (imu_driver...)."},
                        "field": {"type": "string", "description": "The attribute (bias_ready...)."},
                        "value": {"type": ["boolean", "number", "string", "null"]}})

OPERATOR_INPUT = _obj("beastbt.OperatorInput",
                      "What the operator did from outside the tree (a console control, a typed answer), "
                      "at the tick it counted in: beastbt replay does it again there.", {
                          "tick": _TICK,
                          "now_s": {"type": "number", "description": "Clock time it was carried out at, seconds."},
                          "source": {"type": "string", "description": "console or terminal."},
                          "control": {"type": "string",
                                      "description": "pause, resume, abort, answer, teleop, stick_silent; "
                                                     "live tuning: tune, tune_reset, tune_saved."},
                          "body": {"type": "object", "description": "The control's body ({id, choice} for an "
                                                                    "answer; {linear, angular, deadman} for teleop; "
                                                                    "{name, value} for tune)."}})

EVENT = _obj("beastbt.Event", "One run event (clock seconds, a kind word, a text).", {
    "time_s": {"type": "number"}, "kind": {"type": "string"}, "text": {"type": "string"}})

TRUTH = _obj("beastbt.Truth", "The simulated robot's true state (world ENU metres, rad, m/s, rad/s, V).", {
    "t_s": _NUM, "x": _NUM, "y": _NUM, "yaw": _NUM, "v_mps": _NUM, "w_rps": _NUM, "left_m": _NUM,
    "right_m": _NUM, "pan_rad": _NUM, "tilt_rad": _NUM, "battery_v": _NUM})

SIM_CONTACT = _obj("beastbt.SimContact",
                   "The simulator's contact truth, sampled (5 Hz, and at each new contact): world ENU metres.", {
                       "t_s": {"type": "number", "description": "Simulated time, s."},
                       "clearance_m": {"type": ["number", "null"],
                                       "description": "Gap between the footprint and the nearest wall or obstacle now, "
                                                      "m (negative inside; null: nothing to touch)."},
                       "collisions": {"type": "integer", "minimum": 0,
                                      "description": "Distinct contacts so far (the summary's truth.collisions)."},
                       "in_contact": {"type": "boolean"},
                       "persons": {"type": "array", "description": "Each person where it is now: [x, y, radius], m.",
                                   "items": {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3}}})

LOCALISATION_QUALITY = _obj("beastbt.LocalisationQuality",
                            "How the localisation on the mission's map matches (2 Hz): docs/localisation.md.", {
                                "match_quality": {"type": "number", "minimum": 0, "maximum": 1,
                                                  "description": "Share of the scan's beams ending within "
                                                                 "match_tolerance_m of an occupied cell."},
                                "localized": {"type": "boolean", "description": "map_pose.localized."},
                                "updates": {"type": "integer", "minimum": 0, "description": "Filter updates so far."},
                                "particles": {"type": "integer", "minimum": 0, "description": "Number of particles."}})

VISION_ANSWER = _obj("beastbt.VisionAnswer",
                     "One detector run of the mission's camera words (sees, dock, track, photo): what it answered, "
                     "about which frame (beastbt.vision.answer_messages). beastbt replay gives it back instead of "
                     "running the detector again on the recorded JPEG images.", {
                         "now_s": {"type": "number", "description": "Clock time of the tick it ran in, s."},
                         "kind": {"type": "string", "description": "tags:<families>, qr, motion or colour:<name>."},
                         "seq": {"type": "integer", "description": "The camera frame's number (as /sensors/camera)."},
                         "stamp_s": {"type": "number", "description": "When the frame was taken, clock s."},
                         "size": {"type": "array", "items": {"type": "integer"},
                                  "description": "The frame's [width, height], px."},
                         "still": {"type": ["boolean", "null"], "description": "Motion only: the robot stood still."},
                         "value": {"description": "tags: [{family, id, corners_px, size_m, rvec, tvec_m, position_m, "
                                                  "facing_rad}] (camera frame m, rad; position in the base frame); "
                                                  "qr: [{text, corners_px}]; motion: {area_frac, box_px, moving, "
                                                  "warm}; colour: the largest blob {area_frac, centre_px, box_px} "
                                                  "or null. Arrays as {data, dtype}."}},
                     ["now_s", "kind", "seq", "stamp_s", "size", "value"])

GENERIC_READING = {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "beastbt.Reading",
                   "description": "A reading type this version of the recorder has no schema for (its fields).",
                   "type": "object", "required": ["stamp_s"]}

# -- the channel table -------------------------------------------------------------------

CHANNELS: dict[str, dict] = {
    # every sensor stream as it arrived (log time = the tick that received it)
    "/sensors/gps": GPS_FIX,
    "/sensors/imu": IMU_SAMPLE,
    "/sensors/odometry": WHEEL_ODOMETRY,
    "/sensors/battery": BATTERY_STATE,
    "/sensors/joystick": JOYSTICK_STATE,
    "/sensors/line": LINE_OBSERVATION,
    "/sensors/camera": CAMERA_FRAME_INFO,
    # Foxglove views (foxglove.* schemas; frames named by the profile's frames:)
    "/gps/fix": FOXGLOVE_LOCATION_FIX,  # one per GNSS epoch (GGA and RMC merged)
    "/gps/fused": FOXGLOVE_LOCATION_FIX,  # the EKF's fused position on Earth
    "/tf": FOXGLOVE_FRAME_TRANSFORMS,  # map -> odom -> base_link -> camera_link -> camera_optical, every tick
    "/odom": FOXGLOVE_ODOMETRY,  # the dead-reckoning estimate, base_link in odom
    "/scene": FOXGLOVE_SCENE_UPDATE,  # walls, line track, places, route, fences, footprint: at the start and on change
    "/route": FOXGLOVE_GEOJSON,  # the mission's places, route and fences and the world's walls and lines, lon/lat
    "/pose/fused": FOXGLOVE_POSE_IN_FRAME,
    "/camera/image": FOXGLOVE_COMPRESSED_IMAGE,
    "/camera/calibration": FOXGLOVE_CAMERA_CALIBRATION,  # with every image, its size (pinhole, no distortion)
    "/camera/annotations": FOXGLOVE_IMAGE_ANNOTATIONS,  # the detected line, its look-ahead point, a junction
    "/camera/photo": FOXGLOVE_COMPRESSED_IMAGE,  # each photo and snapshot the mission took, full resolution
    "/camera/detections": FOXGLOVE_IMAGE_ANNOTATIONS,  # tags, QR codes, colour blob, motion: per frame looked at
    "/camera/tags": FOXGLOVE_SCENE_UPDATE,  # each tag seen, a plate at its pose (base_link at the frame's time)
    "/scan": FOXGLOVE_LASER_SCAN,  # each LiDAR revolution, in the lidar frame (0 = no return)
    "/costmap": FOXGLOVE_GRID,  # the local costmap (odom frame, uint8 Nav2 costs), at most 2 Hz when it changed
    "/local_plan": FOXGLOVE_SCENE_UPDATE,  # the local planner's path (odom frame), at most 5 Hz when it changed
    "/map": FOXGLOVE_GRID,  # the mission's saved map (map frame, int8 occupancy as nav_msgs), once and on change
    "/path": FOXGLOVE_SCENE_UPDATE,  # the path go_to plans on the map (map frame), when it is planned
    "/global_costmap": FOXGLOVE_GRID,  # the global costmap (odom on GPS, map on a map; uint8 Nav2 costs), 1 Hz
    "/plan": FOXGLOVE_SCENE_UPDATE,  # the way round a GPS go_to follows (odom frame), each time it changes
    "/map/pose": FOXGLOVE_POSE_IN_FRAME,  # the pose on the saved map (map frame), 5 Hz
    "/collision_monitor/zones": FOXGLOVE_SCENE_UPDATE,  # stop and slow polygons (base_link), bold when acting
    "/sim/persons": FOXGLOVE_SCENE_UPDATE,  # the simulator's persons where they are now (map frame), 5 Hz
    "/localisation/particles": FOXGLOVE_SCENE_UPDATE,  # on a map: up to 200 particles (map frame), 2 Hz
    "/localisation/quality": LOCALISATION_QUALITY,  # on a map: match quality and localized, 2 Hz
    "/log": FOXGLOVE_LOG,
    # estimates
    "/estimate/fused": FUSED_POSE,
    "/estimate/odom": FUSED_POSE,
    # commands at each stage
    "/cmd/mission": STAGE_COMMAND,
    "/cmd/teleop": STAGE_COMMAND,
    "/cmd/mux": STAGE_COMMAND,
    "/cmd/gate": STAGE_COMMAND,
    "/cmd/servo": SERVO_COMMAND,
    "/devices/state": DEVICE_STATE,
    "/operator/input": OPERATOR_INPUT,
    "/vision/answers": VISION_ANSWER,  # each detector run of the camera words: what it answered (for replay)
    # the tree, events, failsafes, truth
    "/tree": TREE_CHANGES,
    "/events": EVENT,
    "/failsafes": EVENT,
    "/truth": TRUTH,
    "/sim/contact": SIM_CONTACT,  # truth clearance, collisions and persons (simulator), 5 Hz and at each contact
}
"""Topic -> JSON Schema. ``/cmd/gate`` is what the base adapter was told to send, one message per tick."""

SENSOR_TOPICS: dict[str, str] = {
    "GpsFix": "/sensors/gps", "ImuSample": "/sensors/imu", "WheelOdometry": "/sensors/odometry",
    "BatteryState": "/sensors/battery", "JoystickState": "/sensors/joystick", "LineObservation": "/sensors/line",
    "CameraFrame": "/sensors/camera",
}
"""Reading class name -> its sensor channel (other reading types go to ``/sensors/<snake_name>``)."""


def schema_bytes(schema: dict) -> bytes:
    """The schema as the bytes stored in the MCAP Schema record."""
    return json.dumps(schema, separators=(",", ":"), sort_keys=True).encode()


__all__ = ["OFFSET_KEY", "CHANNELS", "SENSOR_TOPICS", "GENERIC_READING", "schema_bytes"]
