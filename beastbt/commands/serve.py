"""``beastbt serve --robot PROFILE [--sim] --fleet ENDPOINT``: a robot on the fleet that runs the station's missions.

The robot says it is alive on the fleet and waits (status ``idle``). Each
mission that comes on ``beastbt/<name>/mission`` (YAML, or a zip with the
files it names) is checked and assembled exactly as ``beastbt run`` does it
(:func:`beastbt.assembly.prepare`: recorded, with every safety part): the
answer is the validation errors as ``beastbt validate`` prints them, or
``started``; then it runs, and the robot waits again. The files a mission
names are read only inside the robot's mission folder (``--missions-dir``)
for a YAML, inside the zip for a zip, or among the shipped worlds and maps by
name (:mod:`beastbt.core.file_refs`). On the simulator
(``--sim``, or ``--robot sim``) a mission runs at real time unless ``--speed``
says otherwise, so that people can watch. The robot keeps working when the
fleet link drops: a mission under way goes on (unless it requires the
station's supervision, ``fleet: supervision: required``).

Exit status: 0 when stopped (Ctrl-C, SIGTERM), 2 invalid input.
"""

from __future__ import annotations

import argparse
import io
import queue
import shutil
import signal
import sys
import tempfile
import threading
import time
import zipfile
from pathlib import Path, PurePosixPath
from typing import Any, Optional

EXIT_SUCCESS, EXIT_FAILURE, EXIT_INVALID = 0, 1, 2
ZIP_MAX_FILES = 200
"""The most files a mission's zip may hold."""
ZIP_MAX_BYTES = 32 << 20
"""The most a mission's zip may unpack to (bytes)."""
STATION_UNSEEN_S = 10.0
"""How long a robot waits for its station before it says what to check (wall s): TLS refused quietly otherwise."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``beastbt serve``."""
    from beastbt.commands.run import _non_negative_int, add_fleet_arguments
    p.add_argument("--robot", default="sim", help="the robot profile (default: the simulator's, 'sim')")
    p.add_argument("--sim", action="store_true", help="run the profile on the simulator (same geometry and limits)")
    p.add_argument("--world", help="simulated world (default: each mission's 'world:')")
    p.add_argument("--seed", type=_non_negative_int, default=0, help="random seed of the simulator (default 0)")
    p.add_argument("--speed", default="realtime",
                   help="on the simulator: realtime (default, so that people can watch), max, or a factor such as 10")
    p.add_argument("--runs-dir", default="runs", help="where run folders go (default: ./runs)")
    p.add_argument("--missions-dir", default=".", metavar="DIR",
                   help="the robot's mission folder: a mission sent as YAML reads the files it names (world, map, "
                        "route files) inside DIR only, as if it were saved there (default: the current folder)")
    p.add_argument("--no-record", action="store_true", help="do not write run folders")
    from beastbt.commands.run import _positive_int
    p.add_argument("--keep-runs", type=_positive_int, metavar="N",
                   help="keep the newest N finished runs in --runs-dir, pruning older ones as each run starts")
    from beastbt.commands.run import _checked, _endpoint
    p.add_argument("--console", metavar="[HOST:]PORT", type=_checked(_endpoint("--console")),
                   help="serve each mission's operator console there (tree, video, joystick); the station's page "
                        "links to it")
    add_fleet_arguments(p)
    from beastbt.ros2.cli import add_ros2_arguments
    add_ros2_arguments(p)


def command(args: argparse.Namespace) -> int:
    """Serve missions until Ctrl-C or SIGTERM."""
    from beastbt.commands.paths import output_folder_problem
    from beastbt.commands.run import fleet_options
    from beastbt.core.errors import InvalidInput
    from beastbt.run.session import RunOptions, parse_speed
    if args.fleet is None and args.fleet_config is None:
        print("beastbt serve: error: a robot serves a fleet: add --fleet tls/STATION:7447 (with the station's "
              "enrolment; or --fleet-config FILE)", file=sys.stderr)
        return EXIT_INVALID
    try:
        speed = parse_speed(args.speed)
    except ValueError as exc:
        print(f"beastbt serve: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    problem = None if args.no_record else output_folder_problem("--runs-dir", args.runs_dir)
    if problem is None and not Path(args.missions_dir).is_dir():
        problem = f"--missions-dir {args.missions_dir}: no such folder"
    if problem is not None:
        print(f"beastbt serve: error: {problem}", file=sys.stderr)
        return EXIT_INVALID
    fleet, problem = fleet_options(args, "serve")
    if problem is not None:
        print(problem, file=sys.stderr)
        return EXIT_INVALID
    from beastbt.ros2.cli import ros2_options
    ros2, problem = ros2_options(args, "serve")
    if problem is not None:
        print(problem, file=sys.stderr)
        return EXIT_INVALID
    from beastbt.fleet.agent import FleetAgent
    from beastbt.fleet.run_link import robot_name
    from beastbt.robot.profile import load_profile
    try:
        profile = load_profile(args.robot)
        name = robot_name(fleet, profile)
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return EXIT_INVALID
    try:
        agent = FleetAgent(name, fleet, takes_missions=True).start()
    except InvalidInput as exc:  # a --fleet-config that is not one
        print(exc.format(), file=sys.stderr)
        return EXIT_INVALID
    if args.sim or args.robot == "sim":  # it stands at its world's start (where others see it) with a full battery
        try:
            if args.world:
                from beastbt.fleet.shared_world import sim_field
                from beastbt.sim.robot import build_simulator
                from beastbt.sim.world import load_world
                sim = build_simulator(profile, load_world(args.world), args.seed)
                agent.stand(sim_field(sim), sim.truth.battery_v)
            else:  # each mission's own world: until the first, the default world's start (no simulator built yet)
                from beastbt.sim.world import empty_world
                world = empty_world()
                agent.stand({"x": world.start_x, "y": world.start_y, "yaw": world.start_yaw},
                            world.battery_start_v, shared=False)
        except InvalidInput as exc:
            agent.close()
            print(exc.format(), file=sys.stderr)
            return EXIT_INVALID
    from dataclasses import replace
    options = RunOptions(robot=args.robot, world=args.world, seed=args.seed, speed=speed, runs_dir=args.runs_dir,
                         record=not args.no_record, simulate=args.sim, fleet=replace(fleet, agent=agent),
                         keep_runs=args.keep_runs,
                         console=args.console, ros2=ros2)
    missions_dir = Path(args.missions_dir).resolve()
    serving = None
    if ros2 is not None:
        from beastbt.ros2.serving import Ros2Serving
        serving = Ros2Serving(agent, profile, ros2, args.world)
        options.ros2 = serving.run_option()
        serving.idle()
    keys = f" with the keys of {fleet.config_file}" if fleet.config_file and fleet.endpoint else ""
    print(f"robot '{name}' serving the fleet at {fleet.endpoint or fleet.config_file}{keys}: waiting for missions",
          flush=True)
    from beastbt.run.sd_notify import process_notifier
    notifier = process_notifier()
    notifier.ready(f"robot {name}: waiting for missions")
    done = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: done.set())
    unseen_since: Optional[float] = time.monotonic()
    try:
        while not done.is_set():
            notifier.watchdog()  # under systemd: fed while idle too, so a hung wait is restarted
            try:
                request = agent.missions.get(timeout=0.25)
            except queue.Empty:
                if unseen_since is not None and agent.station_present:
                    unseen_since = None
                elif unseen_since is not None and time.monotonic() - unseen_since > STATION_UNSEEN_S:
                    unseen_since = None  # said once: a station that comes later is found all the same
                    print(station_unseen_hint(fleet), file=sys.stderr, flush=True)
                continue
            signal.signal(signal.SIGTERM, previous)  # during a run, the run's own: stop, summary, recording
            try:
                if serving is not None:
                    serving.busy()  # the run's own ROS 2 link takes the port
                summary = serve_one(agent, request, options, missions_dir)
                if summary is not None and interrupted(summary):
                    done.set()  # Ctrl-C or SIGTERM during a mission stops it (as 'run' does) and the serving too
            except Exception as exc:  # noqa: BLE001 - the robot was stopped by the run's end; it serves on
                request.answer(False, {"status": 500, "error": f"the robot could not run it: {type(exc).__name__}"})
                print(f"beastbt serve: internal error in a mission: {type(exc).__name__}: {str(exc)[:300]}",
                      file=sys.stderr, flush=True)
            finally:
                agent.mission_done()
                if serving is not None:
                    serving.idle()
                signal.signal(signal.SIGTERM, lambda signum, frame: done.set())
            if not done.is_set():
                print(f"robot '{name}': waiting for missions", flush=True)
                notifier.status(f"robot {name}: waiting for missions")
    except KeyboardInterrupt:
        pass
    finally:
        notifier.stopping()
        signal.signal(signal.SIGTERM, previous)
        if serving is not None:
            serving.close()
        agent.close()
    return EXIT_SUCCESS


def station_unseen_hint(fleet: Any) -> str:
    """What a robot says when it has not seen its station for :data:`STATION_UNSEEN_S`: what to check."""
    endpoint = fleet.endpoint or "the endpoint in " + str(fleet.config_file)
    if fleet.config_file:
        return (f"beastbt serve: warning: no station seen at {endpoint} yet (the robot keeps trying): is the station "
                f"up there, and is its certificate valid for that name or address? ('beastbt station' prints the "
                f"names; add one with --host NAME) Are these keys of that station's enrolment?")
    return f"beastbt serve: warning: no station seen at {endpoint} yet (the robot keeps trying): is it up there?"


def interrupted(summary: dict) -> bool:
    """Whether the run was ended by Ctrl-C or SIGTERM (its ``mission_end`` event says so)."""
    return any(e.get("kind") == "mission_end" and "interrupted (" in e.get("text", "")
               for e in summary.get("events", []))


def serve_one(agent: Any, request: Any, options: Any, missions_dir: Optional[Path] = None) -> Optional[dict]:
    """Check, answer and run one mission request; the run's summary, or None when it was refused. A YAML mission
    reads the files it names inside ``missions_dir`` (the robot's mission folder; default: the current folder)."""
    from beastbt.assembly import prepare
    from beastbt.core.errors import InvalidInput
    from beastbt.robot.hardware import DeviceUnavailable
    from beastbt.run.run_folder import RunFolderUnavailable
    from beastbt.run.session import execute
    from beastbt.core.file_refs import FileRefs
    folder = Path(tempfile.mkdtemp(prefix="beastbt-mission-"))
    missions_dir = (missions_dir or Path(".")).resolve()
    try:
        text: Optional[str] = None
        try:
            if is_zip(request.payload):
                path = unpack(request.payload, folder)
                refs = FileRefs.inside(folder, "the mission's zip", "the mission's folder in the zip")
            else:
                # a YAML reads its files as if it were saved in the robot's mission folder (nothing is written there)
                text = mission_text(request.payload)
                path = missions_dir / "mission.yaml"
                refs = FileRefs.inside(missions_dir, "the robot's mission folder",
                                       "the robot's mission folder (beastbt serve --missions-dir)")
                if getattr(request, "on_robot", False):  # made from the robot's own profile, not from the network
                    from beastbt.core.file_refs import CLI
                    refs = CLI
        except ValueError as exc:
            request.answer(False, {"status": 400, "error": str(exc)})
            return None
        try:
            prepared = prepare(str(path), options, mission_text=text, refs=refs)
        except InvalidInput as exc:
            request.answer(False, {"status": 422, "error": "the mission is not valid: nothing moved",
                                   "errors": _relative(exc.format(), folder, missions_dir)})
            return None
        except (DeviceUnavailable, RunFolderUnavailable) as exc:
            request.answer(False, {"status": 503, "error": str(exc)})
            return None
        warnings = [_relative(w.format(), folder, missions_dir) for w in prepared.warnings]
        request.answer(True, {"started": prepared.mission.name, "warnings": warnings})
        print(f"mission '{prepared.mission.name}' from the station", flush=True)
        return execute(prepared, sys.stdout)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _relative(text: str, *folders: Path) -> str:
    """``text`` with the robot's own folders taken off the paths in it (``mission.yaml:3:5``, not ``/tmp/...``)."""
    for folder in folders:
        if str(folder) != "/":
            text = text.replace(f"{folder}/", "")
    return text


def is_zip(payload: bytes) -> bool:
    """Whether a mission's bytes are a zip (its local file header's signature), not a YAML text."""
    return payload.startswith(b"PK\x03\x04")


def mission_text(payload: bytes) -> str:
    """A mission sent as YAML, as text; ValueError when it is not UTF-8 text."""
    try:
        return payload.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError("the mission is neither UTF-8 YAML text nor a zip: send the mission's YAML, or a zip with "
                         "mission.yaml and the files it names") from None


def unpack(payload: bytes, folder: Path) -> Path:
    """Write a mission (YAML, or a zip with its files) into ``folder``; the mission file's path. ValueError when the
    zip is not one beastbt takes (a path out of the folder, too large, no single mission at its top)."""
    if not payload.startswith(b"PK\x03\x04"):
        path = folder / "mission.yaml"
        path.write_bytes(payload)
        return path
    try:
        archive = zipfile.ZipFile(io.BytesIO(payload))
    except zipfile.BadZipFile:
        raise ValueError("the mission looks like a zip but cannot be read as one") from None
    members = [m for m in archive.infolist() if not m.is_dir()]
    if len(members) > ZIP_MAX_FILES or sum(m.file_size for m in members) > ZIP_MAX_BYTES:
        raise ValueError(f"the zip holds more than {ZIP_MAX_FILES} files or {ZIP_MAX_BYTES >> 20} MB unpacked")
    for m in members:
        parts = PurePosixPath(m.filename).parts
        if m.filename.startswith("/") or ".." in parts or "\\" in m.filename:
            raise ValueError(f"the zip's file '{m.filename[:80]}' would land outside the mission's folder")
        target = folder.joinpath(*parts)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(archive.read(m))
    tops = [m.filename for m in members if "/" not in m.filename and m.filename.endswith((".yaml", ".yml"))]
    if "mission.yaml" in tops:
        return folder / "mission.yaml"
    if len(tops) != 1:
        raise ValueError("the zip must hold its mission at the top as mission.yaml (or as its only .yaml file), "
                         f"not {', '.join(tops) or 'no YAML file'}")
    return folder / tops[0]
