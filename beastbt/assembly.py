"""The composition root: the one place a robot is assembled, from its profile and an explicit list of parts.

Every way of running a mission comes through here: ``beastbt run`` and
``beastbt tree``, the testing harness (:mod:`beastbt.testing`), the Python
API (:func:`prepare` then :func:`beastbt.run.session.execute`) and ``beastbt
replay``. :func:`assemble` builds the robot for one of three modes:

* **real** (:data:`~beastbt.robot.part.REAL`): the base and every device on
  the robot's own ports;
* **simulator** (:data:`~beastbt.robot.part.SIM`): the same drivers talking
  to emulators behind the same ports, in a world (the default);
* **replay** (:data:`~beastbt.robot.part.REPLAY`): a recording's readings in
  place of every device (the caller hands over that ``RobotIO``).

and then, whatever the mode, the same steps: every part attaches, the first
part with an estimator gives it, the steps of every part join the language's
own, the run is built (which wires the mux, the gate, the e-stop latch and the
command watchdog around the base: no run exists without them), and every part
installs its hooks.

The parts are listed in :data:`BUILTIN_PARTS`, in attach order (the order
fixes which random numbers each emulator draws, so a seed gives the same run).
Each is imported only when the robot profile or the run uses it. Parts from
other packages plug in through the ``beastbt.parts`` entry-point group: a
profile names them in its ``parts:`` section (``parts: {blinker: {pin: 5}}``)
and only those are loaded, by name, as python-can loads its interfaces.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Mapping, Optional, Sequence

from beastbt.behaviours.context import MissionContext, RunServices
from beastbt.core.clock import Clock, SimClock, WallClock
from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.core.events import EventLog
from beastbt.mission.compile import CORE_STEPS, Behaviour, StepBuilder, compile_mission
from beastbt.mission.model import Mission, load_mission
from beastbt.robot.part import REAL, REPLAY, SIM, BasePart, Build, Part, asleep
from beastbt.robot.profile import RobotProfile, load_profile
from beastbt.run.session import Prepared, RunOptions

if TYPE_CHECKING:
    from beastbt.robot.robot_io import RobotIO
    from beastbt.sim.world import World
# The tick loop, the run folder and the world are imported where a run is assembled: `beastbt tree` (which only
# compiles) starts without them.

PART_ENTRY_POINTS = "beastbt.parts"
"""Entry-point group of parts from other packages: ``name = "package.module:PartClass"``."""


@dataclass(frozen=True)
class PartEntry:
    """One built-in part: its name, where it lives (``module:Class``), when a run needs it, what it gives.

    ``capability`` is the word a device part adds to the robot's capabilities
    when it attaches (``gps``, ``camera``...; ``real_only`` when it attaches
    nothing on the simulator), so that a tree can be compiled for a profile
    without opening or emulating its devices.
    """

    name: str
    target: str
    needed: Callable[[RobotProfile, RunOptions], bool]
    capability: Optional[str] = None
    real_only: bool = False
    for_mission: Optional[Callable[[Mission], bool]] = None
    """When given, the part is needed only by a mission for which this holds (``map:``: the localisation)."""

    def needed_by(self, profile: RobotProfile, options: RunOptions, mission: Optional[Mission]) -> bool:
        """Whether a run of ``mission`` (None: any) on ``profile`` with ``options`` needs this part."""
        if not self.needed(profile, options):
            return False
        return self.for_mission is None or (mission is not None and self.for_mission(mission))

    def load(self) -> Part:
        """Import the part's module and make the part."""
        return _instantiate(_import_target(self.target), self.name)


def _has(section: str) -> Callable[[RobotProfile, RunOptions], bool]:
    return lambda profile, options: profile.section(section) is not None


def _always(profile: RobotProfile, options: RunOptions) -> bool:
    return True


BASES: Mapping[str, str] = {
    "waveshare_serial": "beastbt.parts.waveshare:WaveshareBasePart",
    "can": "beastbt.parts.can_base:CanBasePart",
    "pwm": "beastbt.parts.pwm_base:PwmBasePart",
}
"""Profile ``base.type`` -> the base part that opens it. On the simulator a type without one runs on the Waveshare emulator."""

DEFAULT_BASE = "waveshare_serial"

BUILTIN_PARTS: tuple[PartEntry, ...] = (
    # Devices, in attach order (the base is opened first, by BASES).
    PartEntry("servos", "beastbt.parts.servo_board:ServoBoardPart", _has("servos"), "pwm_servos"),
    PartEntry("gps", "beastbt.parts.gps:GpsPart", _has("gps"), "gps"),
    PartEntry("imu", "beastbt.parts.imu:ImuPart", _has("imu"), "imu"),
    PartEntry("lidar", "beastbt.parts.lidar:LidarPart", _has("lidar"), "lidar"),
    PartEntry("camera", "beastbt.parts.camera:CameraPart", _has("camera"), "camera"),
    PartEntry("joystick", "beastbt.parts.joystick:JoystickPart", _has("joystick"), "joystick", real_only=True),
    # What the run does with them.
    PartEntry("navigation", "beastbt.parts.navigation:NavigationPart", _always),
    PartEntry("map_building", "beastbt.parts.map_building:MapBuildingPart",
              lambda profile, options: options.build_map is not None),
    PartEntry("line_following", "beastbt.parts.line_following:LineFollowingPart", _always),
    PartEntry("vision", "beastbt.parts.vision:VisionPart", _always),
    PartEntry("teleop", "beastbt.parts.teleop:TeleopPart", _always),
    PartEntry("map_localisation", "beastbt.parts.map_localisation:MapLocalisationPart", _always,
              for_mission=lambda mission: mission.map_file is not None),
    # What the run shows and keeps.
    PartEntry("recording", "beastbt.parts.recording:RecordingPart",
              lambda profile, options: bool(options.record or options.record_path or options.foxglove is not None)),
    PartEntry("runs", "beastbt.parts.runs:RunsRetentionPart", lambda profile, options: bool(options.record)),
    PartEntry("video_stream", "beastbt.parts.video_stream:VideoStreamPart",
              lambda profile, options: options.stream is not None),
    PartEntry("console", "beastbt.parts.console:ConsolePart",
              lambda profile, options: options.console is not None),
    # After the console: the fleet shares its state and controls when both are on. Without --fleet, a check
    # that refuses a mission requiring the fleet's supervision (it reads nothing, so it wakes no sensor).
    PartEntry("fleet", "beastbt.parts.fleet:FleetPart", lambda profile, options: options.fleet is not None),
    PartEntry("fleet_check", "beastbt.parts.fleet:UnsupervisedCheck",
              lambda profile, options: options.fleet is None),
    # Without --ros2, a check that refuses a mission with a ros2_goals step (before anything moves).
    PartEntry("ros2_goals_check", "beastbt.parts.ros2:Ros2GoalsCheck", lambda profile, options: options.ros2 is None,
              for_mission=lambda mission: _uses_ros2_goals(mission)),
    # ROS 2 over Zenoh (--ros2): last, so that its remote stick and its topics see every other part installed.
    PartEntry("ros2", "beastbt.parts.ros2:Ros2Part", lambda profile, options: options.ros2 is not None),
)
"""The parts of beastbt itself, in the order they attach and install."""


def _uses_ros2_goals(mission: Mission) -> bool:
    from beastbt.parts.ros2 import uses_ros2_goals
    return uses_ros2_goals(mission)


def _import_target(target: str) -> Any:
    module, _, attr = target.partition(":")
    obj: Any = importlib.import_module(module)
    for name in attr.split(".") if attr else ():
        obj = getattr(obj, name)
    return obj


def _instantiate(factory: Any, name: str) -> Part:
    part = factory() if callable(factory) else factory
    if not isinstance(part, Part):
        raise TypeError(f"part '{name}' ({factory!r}) is not a beastbt.robot.part.Part")
    return part


def external_part(name: str, profile: RobotProfile) -> Part:
    """The part called ``name`` from the ``beastbt.parts`` entry points; InvalidInput when none is installed."""
    from importlib import metadata  # only for a profile naming an external part: it costs every run milliseconds

    found = [ep for ep in metadata.entry_points(group=PART_ENTRY_POINTS) if ep.name == name]
    if not found:
        installed = sorted(ep.name for ep in metadata.entry_points(group=PART_ENTRY_POINTS))
        hint = (f"installed parts: {', '.join(installed)}" if installed
                else "no package providing beastbt parts is installed (entry-point group 'beastbt.parts')")
        raise InvalidInput([_profile_problem(profile, ("parts", name), f"no part called '{name}' is installed", hint)])
    return _instantiate(found[0].load(), name)


def _profile_problem(profile: RobotProfile, path: tuple, message: str, hint: str) -> Problem:
    if profile.doc is not None:
        return profile.doc.problem(path, message, hint, key=True)
    return Problem(str(profile.file or profile.name), Position(), message, hint)


def base_part(profile: RobotProfile, simulated: bool) -> BasePart:
    """The part that opens the profile's base (on the simulator, the Waveshare emulator for a type without its own)."""
    kind = str((profile.section("base") or {}).get("type", DEFAULT_BASE))
    target = BASES.get(kind)
    if target is None:
        if not simulated:
            from beastbt.robot.hardware import DeviceUnavailable
            raise DeviceUnavailable(f"base: type '{kind}' is not supported by this version of beastbt")
        target = BASES[DEFAULT_BASE]
    part = _instantiate(_import_target(target), kind)
    assert isinstance(part, BasePart)
    return part


def parts_for(profile: RobotProfile, options: RunOptions,
              builtin: Sequence[PartEntry] = BUILTIN_PARTS, mission: Optional[Mission] = None) -> list[Part]:
    """The parts a run of ``mission`` on ``profile`` with ``options`` needs: the built-in ones it uses, then the
    profile's ``parts:`` (without a mission, none of the parts only some missions need)."""
    parts = [entry.load() for entry in builtin if entry.needed_by(profile, options, mission)]
    for name in (profile.section("parts") or {}):
        parts.append(external_part(str(name), profile))
    return parts


def step_builders(parts: Sequence[Part]) -> dict[str, StepBuilder]:
    """The language's own steps with every part's added (a part may not redefine a core step)."""
    builders = dict(CORE_STEPS)
    for part in parts:
        for kind, builder in part.steps().items():
            if kind in CORE_STEPS:
                raise ValueError(f"part '{part.name}' redefines the core step '{kind}'")
            builders[kind] = builder
    return builders


def assemble(mission: Mission, profile: RobotProfile, options: RunOptions, mode: str,
             world: Optional[World] = None, io: Optional[RobotIO] = None, clock: Optional[Clock] = None,
             services: Optional[RunServices] = None, parts: Optional[Sequence[Part]] = None) -> Prepared:
    """Assemble the run of ``mission`` on ``profile``'s robot in ``mode``; raise InvalidInput or DeviceUnavailable first.

    ``world`` is the simulated world (:data:`SIM`); ``io`` the recorded robot
    (:data:`REPLAY`); ``clock`` defaults to a simulated clock except on the
    robot. ``io``, when given, is used as the robot instead of opening its
    base (a replay's recorded robot, or a test's fakes); ``parts`` replaces
    the parts the profile and options call for. Nothing moves before the run
    is executed.
    """
    from beastbt.run.run_folder import RunFolder, RunFolderUnavailable, temporary_snapshots
    from beastbt.run.runner import MissionRun
    from beastbt.sim.world import empty_world

    if clock is None:
        clock = WallClock() if mode == REAL else SimClock()
    events = EventLog(clock)
    if parts is None:
        parts = parts_for(profile, options, mission=mission)
    build = Build(mode, profile, clock, events)
    if mode not in (REAL, SIM, REPLAY):
        raise ValueError(f"unknown build mode {mode!r}")
    if io is not None:
        build.io, build.sim = io, io.sim  # a robot opened by the caller (a replay's recording, a test's fakes)
    elif mode == SIM:
        from beastbt.sim.robot import build_simulator
        # --world on a fleet: a world shared with the fleet's other simulated robots (docs/fleet.md)
        build.sim = build_simulator(profile, world if world is not None else empty_world(), options.seed,
                                    shared=options.fleet is not None and bool(options.world))
        build.io = base_part(profile, simulated=True).open_sim(build)
    elif mode == REAL:
        build.io = base_part(profile, simulated=False).open_real(build)
    else:
        raise ValueError("a replay is assembled around the recorded robot's RobotIO: pass io")
    try:
        for part in parts:
            part.attach(build)
        estimator = None
        for part in parts:
            estimator = part.estimator(build)
            if estimator is not None:
                break
        run = MissionRun(mission, profile, build.io, clock, events, services, estimator, step_builders(parts))
        prepared = Prepared(mission, profile, world, run, options, events, clock,
                            warnings=run_warnings(mission, profile, world, mode, options))
        if options.record:
            try:
                prepared.folder = RunFolder.create(options.runs_dir, mission.name, clock)
            except RunFolderUnavailable:
                prepared.abandon()  # nothing moved: close what was opened, then say why
                raise
            run.ctx.services.save_snapshot = prepared.folder.save_snapshot
        elif run.ctx.services.save_snapshot is None:
            run.ctx.services.save_snapshot = temporary_snapshots(mission.name)
        from beastbt.behaviours.ask import OperatorQuestions
        run.ctx.services.questions = OperatorQuestions(events, options.answers)
        demand = set(run.reads())
        if options.record_sensors and any(part.name == "recording" for part in parts):
            # --record-sensors: the recording reads whatever any part fills, so nothing sleeps
            demand.update(fill for part in parts for fill in part.fills)
        sleeping = asleep(parts, demand)
        prepared.reads = frozenset(demand.union(*(part.reads for part in parts if part not in sleeping)))
        for part in sleeping:
            part.sleep(prepared)
        if sleeping:
            events.add("asleep", f"not read by this run, so neither polled nor computed: "
                                 f"{', '.join(part.name for part in sleeping)}")
        for part in parts:
            part.install(prepared)
        # Per-tick work and closing only for the parts that have any: the others cost nothing per tick.
        run.hooks[:0] = [part.tick for part in parts if part.overrides("tick")]
        prepared.closers.extend(part.close for part in parts if part.overrides("close"))
        run.summary_contributors.extend(part.summarise for part in parts if part.overrides("summarise"))
    except BaseException:
        build.io.close()  # whatever was opened is released (the base sends its stop)
        raise
    return prepared


def run_warnings(mission: Mission, profile: RobotProfile, world: Optional[World], mode: str,
                 options: Optional[RunOptions] = None) -> list:
    """The mission's warnings (its places against the world's datum) and those of running it on this robot."""
    from beastbt.mission.warnings import by_position, mission_warnings, robot_warnings, world_warnings
    warnings = list(mission.warnings)
    if world is not None and world.doc is not None:
        warnings = mission_warnings(mission, (world.frame.lat0_deg, world.frame.lon0_deg))
        warnings += world_warnings(mission, world)
    if mode == REPLAY:
        return warnings
    fills = base_part(profile, simulated=mode == SIM).fills
    has_battery = "battery" in fills
    has_joystick = profile.section("joystick") is not None or (options is not None and
                                                               options.joystick_script is not None)
    return by_position(warnings + robot_warnings(mission, profile.max_speed_mps, profile.name, has_battery,
                                                 has_joystick, has_lidar=profile.section("lidar") is not None,
                                                 has_odometry="odometry" in fills))


def prepare(mission_path: str, options: RunOptions, mission_text: Optional[str] = None,
            faults: Optional[Any] = None, refs: Optional[Any] = None) -> Prepared:
    """Load and check the mission, profile and world, and assemble the run; raise InvalidInput before anything moves.

    ``faults`` is a mission test's events and substitutions (:class:`beastbt.testing.faults.TestFaults`, the
    simulator only): its persons join the world, its part the run's parts, its substitutions the tree.
    The files the mission names are read where ``refs`` (a :class:`beastbt.core.file_refs.FileRefs`) allows: by
    default inside ``options.files_inside`` if it is set, else anywhere (the command line).
    """
    from beastbt.core.file_refs import CLI, FileRefs
    from beastbt.mission.mission_world import load_mission_world
    from beastbt.sim.world import empty_world, load_world

    if refs is None:
        refs = FileRefs.inside(options.files_inside, f"the folder {options.files_inside} (--files-inside)") \
            if options.files_inside else CLI
    mission = load_mission(mission_path, text=mission_text, refs=refs)
    profile = load_profile(options.robot)
    if options.simulated:
        if options.world:
            world = load_world(options.world)
        elif mission.world is not None:
            world = load_mission_world(mission)
        else:
            world = empty_world()
        # a world from the command line reads its map as the command line does; the mission's, as the mission
        use_world_map(mission, world, CLI if options.world else None)
        if faults is None:
            return assemble(mission, profile, options, SIM, world=world)
        faults.enter(world)  # the test's persons are in the world before its simulator is built
        parts = [*parts_for(profile, options, mission=mission), faults.part]
        prepared = assemble(mission, profile, options, SIM, world=world, services=faults.services(), parts=parts)
        faults.part.use_lidar(next((getattr(p, "device", None) for p in parts if p.name == "lidar"), None))
        return prepared
    if faults is not None:
        raise ValueError("a mission test's faults are carried out on the simulator only")
    return assemble(mission, profile, options, REAL)


def use_world_map(mission: Mission, world: World, refs: Optional[Any] = None) -> None:
    """A mission that names no ``map:`` of its own localises on its world's ``map:``, if the world has one (the
    path relative to the world file, read where ``refs`` allows: by default where the mission's files may be; a
    missing or bad map is an error at the world's line)."""
    name = world.data.get("map") if world.doc is not None else None
    if mission.map_file is not None or not isinstance(name, str) or world.file is None:
        return
    from beastbt.mission.model import locate_world_map
    locate_world_map(mission, world.doc, world.file, refs)  # where its files may be (beastbt.core.file_refs)


def compile_for_profile(mission: Mission, profile: RobotProfile, simulated: bool = True,
                        on_step: Optional[Callable[[Any, Behaviour], None]] = None) -> Behaviour:
    """The tree ``mission`` compiles to on ``profile``'s robot, without opening or emulating any device.

    The robot's capabilities are those its device parts would give
    (:attr:`PartEntry.capability`); the steps are those of the parts that add
    steps (the device parts of beastbt add none, so they are not imported:
    no OpenCV, no EKF). What ``beastbt tree`` prints.
    """
    options = RunOptions(record=False)
    entries = [entry for entry in BUILTIN_PARTS if entry.needed_by(profile, options, mission)]
    capabilities = frozenset(entry.capability for entry in entries
                             if entry.capability is not None and not (simulated and entry.real_only))
    parts = [entry.load() for entry in entries if entry.capability is None]
    parts += [external_part(str(name), profile) for name in (profile.section("parts") or {})]
    clock = SimClock()
    ctx = MissionContext(clock=clock, events=EventLog(clock), params=profile.control, capabilities=capabilities)
    # on_step: told each step and the behaviour it became (the studio maps nodes back to their steps' lines)
    return compile_mission(mission, ctx, step_builders(parts), on_step)


def run_file(mission_path: str, options: RunOptions) -> dict:
    """Prepare and execute a run (the Python API of ``beastbt run``); return the summary."""
    from beastbt.run.session import execute
    return execute(prepare(mission_path, options))


__all__ = ["assemble", "prepare", "run_file", "compile_for_profile", "parts_for", "base_part", "step_builders", "external_part",
           "BUILTIN_PARTS", "BASES", "PartEntry", "PART_ENTRY_POINTS", "RunOptions", "Prepared"]
