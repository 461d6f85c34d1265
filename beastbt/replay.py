"""``beastbt replay RUN``: feed a recorded run back through the estimator and the tree.

The recorded sensor streams go back in through a :class:`ReplayIO` (a
:class:`~beastbt.robot.robot_io.RobotIO` whose base returns, each tick, the
readings that arrived at that tick) on a :class:`~beastbt.core.clock.SimClock`
set to each recorded tick time, with the mission text and robot profile stored
in the recording. The replay's commands (mission, mux, gate, servos) are then
compared with the recorded ones, tick by tick: a deterministic simulated run
replays with no difference; a field run shows where a changed mission
(``--mission FILE``) or a changed estimator would have acted differently.

What the operator did from outside the tree is given again at the tick it
counted in (:class:`InputPlayer`): the ``--answer`` answers (metadata
``answers``), the console's controls and stick and a terminal's answers
(``/operator/input``), the console's e-stop (its event). A joystick's states
are readings like any other sensor's.

What the camera's detectors answered a mission that uses ``sees``, ``photo``, ``alert``, ``dock`` or ``track``
is given back too (:func:`install_replay_vision`): the recording keeps JPEG images a few times a second, not
the frames the detectors saw, so each detector's answer was recorded (``/vision/answers``) and the replay's
detectors give those for the same frames; only what the recording lacks is computed on its images, and the
notes say which (:func:`vision_notes`).
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np

from beastbt.blackboard import types as bt
from beastbt.blackboard.types import (BatteryState, CameraFrame, GpsFix, ImuSample, JoystickState, LineObservation,
                                      ServoCommand, VelocityCommand, WheelOdometry)
from beastbt.mission.model import load_mission
from beastbt.core.clock import SimClock
from beastbt.robot.profile import load_profile, profile_path
from beastbt.recording.reader import Recording, find_recording, read_recording
from beastbt.robot.robot_io import RobotIO
from beastbt.assembly import assemble
from beastbt.behaviours.context import RunServices
from beastbt.robot.part import REPLAY, Part
from beastbt.run.operator_inputs import CONSOLE, STICK_SILENT, TERMINAL
from beastbt.run.runner import TickRecord
from beastbt.run.safety import request_estop
from beastbt.run.session import RunOptions


# -- rebuilding readings -----------------------------------------------------------------


def _tuple3(v: Any) -> Any:
    return tuple(v) if v is not None else None


def _fields(d: dict) -> dict:
    """A sensor message's reading fields (without where it came from)."""
    return {k: v for k, v in d.items() if k != "source"}


def _gps(d: dict) -> GpsFix:
    d = _fields(d)
    d["covariance_enu"] = tuple(tuple(row) for row in d["covariance_enu"])
    return GpsFix(**d)


def _imu(d: dict) -> ImuSample:
    return ImuSample(d["stamp_s"], tuple(d["gyro_rps"]), tuple(d["accel_mps2"]), _tuple3(d.get("mag_t")),
                     d.get("temperature_c"))


READING_BUILDERS = {
    "/sensors/gps": _gps,
    "/sensors/imu": _imu,
    "/sensors/odometry": lambda d: WheelOdometry(**_fields(d)),
    "/sensors/battery": lambda d: BatteryState(**_fields(d)),
    "/sensors/joystick": lambda d: JoystickState(d["stamp_s"], dict(d["axes"]), dict(d["buttons"]), d["connected"]),
    "/sensors/line": lambda d: LineObservation(**_fields(d)),
}
"""Sensor topic -> message dict to the reading the driver produced (exactly: JSON keeps every float)."""


class ReplayBase:
    """A base adapter that returns the recorded readings of the current tick and remembers what it was sent.

    Each tick :meth:`load` splits the tick's readings by the device they came
    from: :meth:`poll` returns the base's (and those of unknown origin),
    :meth:`sensor_poll` makes the poll of a recorded sensor; the loop then
    polls them in the recorded order, as it did on the robot.
    """

    name = "replay"

    def __init__(self, imu_tap: Any = None) -> None:
        self.pending: list = []
        self.by_sensor: dict[str, list] = {}
        self.sent: list[VelocityCommand] = []
        self.imu_tap = imu_tap

    def load(self, readings: list, sensors: set[str]) -> None:
        """Give this tick's ``(source, reading)`` list to the base and the sensors."""
        self.pending = []
        self.by_sensor = {}
        for source, reading in readings:
            if source in sensors:
                self.by_sensor.setdefault(source, []).append(reading)
            else:
                self.pending.append(reading)

    def sensor_poll(self, name: str):
        """The poll of sensor ``name``: its readings of this tick (IMU device samples also go to the tap)."""
        def poll(now_s: float) -> list:
            out = self.by_sensor.pop(name, [])
            if self.imu_tap is not None:
                # On the robot the IMU device's poll records its samples in the estimator's tap; the
                # base's own IMU never goes there.
                for r in out:
                    if isinstance(r, ImuSample):
                        self.imu_tap.record(r)
            return out
        return poll

    def start(self, now_s: float) -> None:
        """Nothing to start."""

    def send_velocity(self, cmd: VelocityCommand, now_s: float) -> None:
        """Keep the command (m/s, rad/s)."""
        self.sent.append(cmd)

    def emergency_stop(self, now_s: float) -> None:
        """Nothing moves in a replay."""

    def poll(self, now_s: float) -> list:
        """The readings recorded at this tick (every device's, in the order they arrived)."""
        out, self.pending = self.pending, []
        return out

    def close(self) -> None:
        """Nothing to release."""


class ReplayServos:
    """A servo adapter with the recorded robot's servo names; keeps every command it takes."""

    def __init__(self, names: list[str]) -> None:
        self.names = list(names)
        self.taken: list[tuple[float, ServoCommand]] = []

    def servo_names(self) -> list[str]:
        """The recorded robot's servo names."""
        return list(self.names)

    def set_servo(self, cmd: ServoCommand, now_s: float) -> bool:
        """Take commands for the recorded servos (or addressed by channel)."""
        if cmd.name in self.names or (cmd.name is None and cmd.channel is not None):
            self.taken.append((now_s, cmd))
            return True
        return False


class RecordedDevice:
    """Stands in for a device of the recorded robot (a ``RobotIO`` device field) whose recorded states replay sets."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __repr__(self) -> str:
        return f"RecordedDevice({self.name!r})"


class DeviceFlags:
    """Replays /devices/state: before each tick, each watched device attribute takes its recorded value."""

    def __init__(self, rec: Recording, io: RobotIO) -> None:
        self.changes: dict[int, list[tuple[str, str, Any]]] = {}
        for m in rec.topic("/devices/state"):
            self.changes.setdefault(m["tick"], []).append((m["device"], m["field"], m["value"]))
            device = getattr(io, m["device"], None)
            if device is None:
                device = RecordedDevice(m["device"])
                setattr(io, m["device"], device)
            if not hasattr(device, m["field"]):
                setattr(device, m["field"], m["value"])
        self.io = io

    def apply(self, tick: int) -> None:
        """Set the states recorded at ``tick`` (they held from that tick's sensing on)."""
        for device, attr, value in self.changes.get(tick, ()):
            setattr(getattr(self.io, device), attr, value)


CONSOLE_ESTOP = "operator console"
"""The reason the console's e-stop gives (:func:`~beastbt.run.safety.request_estop`), as its event says it."""


class InputPlayer:
    """Replays ``/operator/input``: what the operator did from the console or a terminal, again at its tick.

    A tick hook where the console's own hook was (:meth:`install`): each recorded
    input of the tick under way is carried out through the same code as in
    the run (the console's :class:`~beastbt.live.console_control.ConsoleControls`
    with a wall clock that never lets its stick go silent by itself: the
    recorded ``stick_silent`` says when it did; a typed answer through the
    question board). A run with a console had it from the start (it makes the
    robot drivable by hand): the replay has one too, used or not.
    """

    def __init__(self, rec: Recording, run: Any) -> None:
        self.run = run
        self.inputs: dict[int, list[dict]] = {}
        for m in rec.topic("/operator/input"):
            self.inputs.setdefault(int(m["tick"]), []).append(m)
        # The console's e-stop latches at once from the server's thread, not through a control: its event
        # (clock time of the tick it came in, or of the next) says when.
        self.estops = [float(m["time_s"]) for m in rec.topic("/events")
                       if m["kind"] == "estop" and m["text"].endswith(f": {CONSOLE_ESTOP}")]
        self.controls: Any = None
        if CONSOLE in json.loads(rec.info.get("operator_inputs", "[]")) or any(
                m["source"] == CONSOLE for ms in self.inputs.values() for m in ms):
            from beastbt.live.console_control import ConsoleControls
            self.controls = ConsoleControls(run, wall=lambda: 0.0)

    def install(self) -> None:
        """Put the player where the console's hook is in a run: right after the parts' own tick hooks (the
        assembly puts those first), before the hooks parts add when installed (when there is anything to play)."""
        if not self.inputs and not self.estops:
            return
        hooks = self.run.hooks
        at = next((i for i, h in enumerate(hooks) if not isinstance(getattr(h, "__self__", None), Part)), len(hooks))
        hooks.insert(at, self)

    def __call__(self, run: Any, now_s: float) -> None:
        """Carry out the inputs recorded for this tick, in their order."""
        if self.estops and now_s >= self.estops[0] - 1e-9:
            self.estops.pop(0)
            request_estop(run, CONSOLE_ESTOP)
        for m in self.inputs.pop(run.ticks, ()):
            source, control, body, at_s = m["source"], m["control"], dict(m["body"]), float(m["now_s"])
            if source == CONSOLE and self.controls is not None:
                if control == STICK_SILENT:
                    self.controls.release_silent_stick(at_s)
                else:
                    self.controls.submit(control, body)
                    self.controls.apply_pending(at_s)
            elif source == TERMINAL and control == "answer":
                questions = run.ctx.services.questions
                if questions is not None:
                    questions.answer(str(body.get("id")), body.get("choice"), TERMINAL)


@dataclass
class RecordedTick:
    """One recorded tick: its number, clock time (s), readings, and the commands recorded at each stage."""

    tick: int
    now_s: float
    readings: list
    """``(source, reading)`` in the order they arrived; source ``base``, a sensor's name, or None (unknown)."""
    mission: Optional[dict]
    mux: Optional[dict]
    gate: dict


def recorded_ticks(rec: Recording) -> list[RecordedTick]:
    """The recording as ticks: readings grouped by the tick that received them, and that tick's commands."""
    gates = rec.messages.get("/cmd/gate", [])
    by_time: dict[int, list] = {}
    images: dict[int, np.ndarray] = {}
    recorded_images = rec.messages.get("/camera/image", [])
    if recorded_images:
        import base64

        import cv2  # only runs with a camera need it
    for t, m in recorded_images:
        img = cv2.imdecode(np.frombuffer(base64.b64decode(m["data"]), np.uint8), cv2.IMREAD_COLOR)
        if img is not None:
            images[t] = img
    last_image: Optional[np.ndarray] = None
    blank: dict[tuple[int, int], np.ndarray] = {}
    for topic, t, m in rec.order:
        if topic == "/scan" and "stamp_s" in m:  # LiDAR revolutions are recorded there only
            from beastbt.recording.foxglove import scan_of
            by_time.setdefault(t, []).append((m.get("source"), scan_of(m)))
            continue
        if not topic.startswith("/sensors/"):
            continue
        build = READING_BUILDERS.get(topic)
        if build is not None:
            reading = build(m)
        elif topic == "/sensors/camera":
            image = images.get(t) if m.get("image_recorded") else None
            if image is not None:
                last_image = image
            w, h = int(m["width"]), int(m["height"])
            if image is None or image.shape[:2] != (h, w):
                # Only some frames were recorded: reuse the last picture of the right size (or grey).
                if last_image is not None and last_image.shape[:2] == (h, w):
                    image = last_image
                else:
                    image = blank.setdefault((h, w), np.full((h, w, 3), 128, np.uint8))
            reading = CameraFrame(m["stamp_s"], image, int(m["seq"]))
        else:
            name = rec.schemas.get(topic, ("", {}))[0].rpartition(".")[2]
            cls = getattr(bt, name, None)
            if cls is None:
                continue
            try:
                reading = cls(**_fields(m))
            except TypeError:
                continue
        by_time.setdefault(t, []).append((m.get("source"), reading))
    mission = {m["tick"]: m for m in rec.topic("/cmd/mission")}
    mux = {m["tick"]: m for m in rec.topic("/cmd/mux")}
    out = []
    for t, g in gates:
        k = g["tick"]
        out.append(RecordedTick(k, g["now_s"], by_time.get(t, []), mission.get(k), mux.get(k), g))
    return out


# -- the replay ------------------------------------------------------------------------------


def install_replay_vision(rec: Recording, mission: Any, profile: Any, run: Any, clock: SimClock) -> Any:
    """The camera words' detectors for the replay (``ctx.services.vision``), as the vision part installs them in a
    run, answering from the recording's ``/vision/answers``: a
    :class:`~beastbt.vision.recorded_answers.ReplayVisionWatch` (None when the mission does not ask the camera or
    the recorded robot has none)."""
    from beastbt.parts.vision import vision_uses
    if profile.section("camera") is None or "camera" not in run.io.capabilities:
        return None
    if not vision_uses(mission.doc.data if mission.doc is not None else {}):
        return None
    from beastbt.devices.camera import CameraConfig
    from beastbt.parts.vision import _gimbal_reader  # the gimbal as the run's watch reads it (sent servo angles)
    from beastbt.robot.profile import section_config
    from beastbt.vision.camera_model import CameraGeometry
    from beastbt.vision.recorded_answers import TOPIC, RecordedAnswers, ReplayVisionWatch, replay_frames
    answers = RecordedAnswers(rec.topic(TOPIC)) if TOPIC in rec.messages else None
    geometry = CameraGeometry.from_config(section_config(profile, "camera", CameraConfig))
    # The frame vision looks at is the newest the replay handed over, as the camera pipeline's newest in a run.
    latest = replay_frames(lambda: run.latest.get(CameraFrame), clock.now, answers)
    watch = ReplayVisionWatch(latest, geometry, _gimbal_reader(), answers=answers)
    run.ctx.services.vision = watch
    return watch


def vision_notes(rec: Recording, watch: Any) -> list[str]:
    """What the replay's notes say about the camera: whether the detectors' answers were the recorded ones."""
    images = rec.messages.get("/camera/image")
    frames = rec.messages.get("/sensors/camera")
    if watch is None:
        if frames and not images:
            return ["camera frames were recorded without pixels: vision in the tree sees grey images"]
        return []
    notes = []
    if not frames:
        return ["the recorded run took no camera frames (its mission did not look): this mission's camera words see "
                "none, so each {sees: ...} is unknown and photo, dock and track fail as they do without a frame"]
    answers = watch.answers
    if answers is not None and answers.given:
        notes.append(f"the camera's detectors were not run again: their {answers.given} recorded answers "
                     f"(/vision/answers) were given back for the frames they looked at")
    if watch.computed:
        kinds = ", ".join(f"{k} ({n})" for k, n in sorted(watch.computed.items()))
        where = (f"the recorded JPEG images ({len(images)} of {len(frames or images)} frames; the frames between "
                 f"show the last one)" if images else "grey images (the recording holds no camera pixels)")
        why = ("the recording holds none of them (the mission asks what the run did not)" if answers is not None
               else "the recording holds no detector answers (recorded before /vision/answers)")
        if answers is not None and "qr" in watch.computed and rec.info.get("simulated") == "false":
            why += "; on the robot QR codes are read on a worker thread, whose answers are not recorded"
        notes.append(f"detector answers computed again, since {why}: {kinds}, on {where}; they may differ from "
                     f"what the camera showed, and so may what the tree decided on them")
    return notes


NOT_REPLAYED = ("/truth", "/estimate/fused", "/estimate/odom", "/pose/fused", "/gps/fix", "/gps/fused", "/tf", "/odom",
                "/scene", "/route", "/camera/calibration", "/camera/annotations", "/log", "/tree", "/camera/photo",
                "/camera/detections", "/camera/tags")
"""Topics replay does not need: what the run computed is computed again; only inputs and commands are read."""


@dataclass
class Difference:
    """One place where the replay did not do what the recording says: tick, time (s), stage, both values."""

    tick: int
    now_s: float
    stage: str
    recorded: Any
    replayed: Any

    def describe(self) -> str:
        """One line for a person."""
        return f"tick {self.tick} ({self.now_s:.3f} s) {self.stage}: recorded {self.recorded}, replay {self.replayed}"


@dataclass
class ReplayResult:
    """What a replay did: ticks replayed, differences, both final statuses."""

    mission: str
    ticks: int
    duration_s: float
    differences: list[Difference] = field(default_factory=list)
    recorded_status: Optional[str] = None
    replay_status: Optional[str] = None
    truncated_recording: bool = False
    notes: list[str] = field(default_factory=list)
    differing_ticks: int = 0
    """How many ticks had at least one command that differed (all of them, not only those listed)."""
    events: list[tuple[float, str, str]] = field(default_factory=list)
    """The replay's own run events ``(time s, kind, text)``: its steps' outcomes, photos and alerts (a photo's file
    is ``(replay) NAME.jpg``: a replay writes none)."""

    @property
    def identical(self) -> bool:
        """True when every command matched."""
        return not self.differences


def _cmd_text(d: Optional[dict], than: Optional[dict] = None) -> str:
    """A command in words, rounded; with ``than`` (the other command), each field that differs from it by less
    than the rounding shows by how much (``0.1500 m/s (+2.8e-17)``) and the stamps are given."""
    if d is None:
        return "none"

    def field(key: str, fmt: str) -> str:
        text = format(d[key], fmt)
        if than is not None and d[key] != than[key]:
            text += f" ({d[key] - than[key]:+.2g})"
        return text

    if than is None:
        return f"{d['linear_mps']:.4f} m/s {d['angular_rps']:.4f} rad/s ({d['source']}, mux {d['mux_source']})"
    return (f"{field('linear_mps', '.4f')} m/s {field('angular_rps', '.4f')} rad/s at {field('stamp_s', '.3f')} s "
            f"({d['source']}, mux {d['mux_source']})")


def command_texts(recorded: Optional[dict], replayed: Optional[dict]) -> tuple[str, str]:
    """How two differing commands are printed: rounded; when rounding would print them the same, the replayed
    one says by how much each field differs (float noise shows as +2.8e-17, never as 0.15000000000000002)."""
    a, b = _cmd_text(recorded), _cmd_text(replayed)
    if a == b and recorded is not None and replayed is not None:
        a, b = _cmd_text(recorded, recorded), _cmd_text(replayed, recorded)
    return a, b


def _same(rec: Optional[dict], cmd: Optional[VelocityCommand], mux_source: str) -> bool:
    if rec is None or cmd is None:
        return rec is None and cmd is None
    return (rec["linear_mps"] == cmd.linear_mps and rec["angular_rps"] == cmd.angular_rps
            and rec["stamp_s"] == cmd.stamp_s and rec["source"] == cmd.source and rec["mux_source"] == mux_source)


def _as_dict(cmd: Optional[VelocityCommand], mux_source: str) -> Optional[dict]:
    if cmd is None:
        return None
    return {"linear_mps": cmd.linear_mps, "angular_rps": cmd.angular_rps, "stamp_s": cmd.stamp_s,
            "source": cmd.source, "mux_source": mux_source}


def load_profile_of(rec: Recording) -> Any:
    """The robot profile the run used: the recorded text (the file by name when it has not changed since)."""
    robot = rec.info.get("robot", "sim")
    text = rec.text("robot.yaml")
    if text is None:
        return load_profile(robot)
    try:
        unchanged = profile_path(robot).read_text(encoding="utf-8") == text
    except OSError:
        unchanged = False
    if unchanged:
        return load_profile(robot)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / (Path(robot).name if robot.endswith((".yaml", ".yml")) else f"{robot}.yaml")
        path.write_text(text, encoding="utf-8")
        return load_profile(path)


def replay(run_path: str, mission_path: Optional[str] = None, max_differences: int = 1000) -> ReplayResult:
    """Replay the recorded run at ``run_path`` (a run folder or ``.mcap``); optionally with another mission file."""
    rec = read_recording(find_recording(run_path), keep_order=True, skip_topics=NOT_REPLAYED)
    info = rec.info
    if not info:
        raise ValueError(f"{run_path}: not a beastbt run recording (no beastbt.run metadata)")
    if mission_path is not None:
        mission = load_mission(mission_path)
    else:
        text = rec.text("mission.yaml")
        if text is None:
            raise ValueError(f"{run_path}: the recording holds no mission text")
        mission = load_mission(info.get("mission_file") or "mission.yaml", text=text)
    profile = load_profile_of(rec)
    ticks = recorded_ticks(rec)

    base = ReplayBase()
    servo_names = json.loads(info.get("servo_names", "[]"))
    servos = ReplayServos(servo_names)
    io = RobotIO(base=base, servos=[servos] if servo_names else [],
                 capabilities=set(json.loads(info.get("capabilities", "[]"))))
    sensors = [s for s in json.loads(info.get("sensor_sources", "[]")) if s != "base"]
    for name in sensors:
        io.sensors[name] = base.sensor_poll(name)
    devices = set(json.loads(info.get("io_extras", "[]")))  # the recorded robot's devices, by name
    if "joystick" in devices:
        io.joystick = RecordedDevice("joystick")  # teleop asks whether there is one
    if "magnetic_declination_deg" in info:
        io.magnetic_declination_deg = float(info["magnetic_declination_deg"])
    flags = DeviceFlags(rec, io)
    if "imu_tap" in devices:
        from beastbt.estimation.imu_tap import ImuTap
        driver = io.imu_driver
        base.imu_tap = io.imu_tap = ImuTap(
            ready=(lambda: bool(driver.bias_ready)) if driver is not None and hasattr(driver, "bias_ready") else None)
    snapshots: list[str] = []
    services = RunServices(save_snapshot=lambda name, frame: snapshots.append(name) or f"(replay) {name}.jpg")
    # The same assembly as the run, with the recording in place of every device: the same parts
    # (navigation tuning, teleop, line following...) install the same hooks; nothing is recorded.
    options = RunOptions(robot=str(info.get("robot", "sim")), seed=int(info.get("seed", 0) or 0), record=False,
                         answers=json.loads(info.get("answers", "{}")))  # --answer: given again, at the same ask
    substituted = (rec.summary or {}).get("substituted") or []
    if substituted and mission_path is None:  # a mission test forced these steps' results: the same stand-ins
        from beastbt.testing.faults import TestFaults
        from beastbt.testing.spec import Substitution
        forced = [Substitution(str(s["step"]), str(s["result"]), float(s["after_s"])) for s in substituted]
        services.substitute = TestFaults([], forced).services().substitute
    clock = SimClock()
    prepared = assemble(mission, profile, options, REPLAY, io=io, clock=clock, services=services)
    run = prepared.run
    if "ctx_capabilities" in info:
        # What other parts added after the tree was compiled (a scripted joystick...).
        run.ctx.capabilities = frozenset(json.loads(info["ctx_capabilities"]))
    vision = install_replay_vision(rec, mission, profile, run, clock)
    InputPlayer(rec, run).install()
    seen: list[TickRecord] = []
    run.recorders.append(seen.append)

    result = ReplayResult(mission.name, 0, 0.0, truncated_recording=not rec.complete)
    diffs = result.differences
    for rt in ticks:
        if run.status is not None:
            diffs.append(Difference(rt.tick, rt.now_s, "end", "the run goes on",
                                    f"the replay ended ({run.status}) at tick {run.ticks - 1}"))
            break
        if rt.now_s > clock.now():
            clock.set(rt.now_s)
        base.load(rt.readings, set(sensors))
        flags.apply(rt.tick)
        run.tick()
        if not seen or seen[-1].tick != rt.tick:
            diffs.append(Difference(rt.tick, rt.now_s, "tick", f"tick {rt.tick}", "no tick recorded by the replay"))
            break
        got = seen[-1]
        result.ticks += 1
        result.duration_s = rt.now_s
        differs = False
        for stage, recorded, cmd in (("mission", rt.mission, got.cmd_mission), ("mux", rt.mux, got.cmd_mux),
                                     ("gate", rt.gate, got.cmd_gate)):
            if not _same(recorded, cmd, got.mux_source):
                differs = True
                if len(diffs) < max_differences:
                    diffs.append(Difference(rt.tick, rt.now_s, stage,
                                            *command_texts(recorded, _as_dict(cmd, got.mux_source))))
        result.differing_ticks += differs
    # Servo commands: the same names and angles at the same times.
    rec_servos = [(m["now_s"], m["name"], m["angle_rad"], m["channel"], m["pulse_s"]) for m in rec.topic("/cmd/servo")]
    rep_servos = [(t, c.name, c.angle_rad, c.channel, c.pulse_s) for t, c in servos.taken]
    for i in range(max(len(rec_servos), len(rep_servos))):
        a = rec_servos[i] if i < len(rec_servos) else None
        b = rep_servos[i] if i < len(rep_servos) else None
        if a != b:
            diffs.append(Difference(-1, (a or b)[0], "servo", a, b))
            break
    summary = rec.summary
    recorded_status = summary.get("status") if summary else None
    ends = [m for m in rec.topic("/events") if m["kind"] == "mission_end"]
    if recorded_status is None:
        recorded_status = ends[-1]["text"].split(":")[0] if ends else None
    result.recorded_status = recorded_status
    if run.status is None and ends and not diffs:
        # Ended from outside the tree (--max-time, Ctrl-C): the recording stops there, and so does the replay.
        result.notes.append(f"the run was ended from outside the mission ({ends[-1]['text']}): the replay went "
                            f"to the same tick, with nothing after it to replay")
    result.replay_status = run.status
    result.events = [(e.time_s, e.kind, e.text) for e in run.events.events]
    if run.status is not None and recorded_status is not None and run.status != recorded_status:
        diffs.append(Difference(result.ticks - 1, result.duration_s, "outcome", recorded_status, run.status))
    if not rec.complete:
        result.notes.append(f"the recording was cut short ({rec.stopped_because}); replayed what it holds "
                            f"(`beastbt recover RUN` rewrites it as a whole MCAP file for other tools)")
    result.notes.extend(vision_notes(rec, vision))
    return result


__all__ = ["replay", "ReplayResult", "Difference", "ReplayBase", "ReplayServos", "recorded_ticks", "READING_BUILDERS"]
