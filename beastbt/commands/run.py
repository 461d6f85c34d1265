"""``beastbt run MISSION``: run a mission on the simulator (default) or on a robot, and summarise it.

Exit status: 0 the mission succeeded, 1 it failed or was stopped, 2 invalid
input (nothing moved). Every option is checked before anything is loaded.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, Callable, Mapping, Optional

from beastbt.core.units import UnitError, parse_duration

EXIT_SUCCESS, EXIT_FAILURE, EXIT_INVALID = 0, 1, 2


class ReaderSafeStream:
    """Standard output that a reader who went away cannot break: ``beastbt run m.yaml --summary s.json | head -n 0``.

    The first write or flush that finds the pipe closed (BrokenPipeError)
    points the file descriptor at /dev/null and drops what was pending; the run
    carries on to its end and writes its summary and recording, and the exit
    status is the mission's. Everything else is the wrapped stream's.
    """

    def __init__(self, stream: Any) -> None:
        self._stream = stream
        self.reader_gone = False
        """True once a write found the reader gone (what was written since went nowhere)."""

    def _gone(self) -> None:
        import os
        self.reader_gone = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())  # the pending bytes, flushed at exit, go nowhere, quietly
            os.close(devnull)
        except (OSError, ValueError, AttributeError):
            pass

    def write(self, text: str) -> int:
        """Write ``text``; when the reader is gone, nothing, and no error."""
        if not self.reader_gone:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        """Flush; when the reader is gone, nothing, and no error."""
        if not self.reader_gone:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._gone()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def reader_safe_stdout(command: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """Run ``command`` with :class:`ReaderSafeStream` as standard output (every print of the run, its threads'
    included), the stream it replaced put back after."""
    import functools

    @functools.wraps(command)
    def guarded(args: argparse.Namespace) -> int:
        out = ReaderSafeStream(sys.stdout)
        sys.stdout = out  # type: ignore[assignment]
        try:
            return command(args)
        finally:
            out.flush()  # what is still buffered goes now, or nowhere: never a broken pipe at exit (status 120)
            sys.stdout = out._stream
    return guarded


def _duration(text: str) -> float:
    try:
        return parse_duration(text)
    except UnitError as exc:
        raise argparse.ArgumentTypeError(str(exc))


def _checked(parse: Callable[[str], Any]) -> Callable[[str], Any]:
    def convert(text: str) -> Any:
        try:
            return parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc))
    return convert


def _positive_duration(text: str) -> float:
    seconds = _duration(text)
    if not seconds > 0:
        raise argparse.ArgumentTypeError(f"'{text}' is not a positive duration (e.g. '10 min', '90 s')")
    return seconds


def _positive_int(text: str) -> int:
    value = _non_negative_int(text)
    if value == 0:
        raise argparse.ArgumentTypeError("give 1 or more")
    return value


def _non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"'{text}' is negative; give 0 or more")
    return value


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not value >= 0:  # also refuses nan
        raise argparse.ArgumentTypeError(f"'{text}' is negative; give 0 or more (0: none)")
    return value


def _positive_float(text: str) -> float:
    value = _non_negative_float(text)
    if value == 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be more than 0")
    return value


def _quality(text: str) -> int:
    value = _non_negative_int(text)
    if not 1 <= value <= 100:
        raise argparse.ArgumentTypeError(f"'{text}' is not a JPEG quality 1-100")
    return value


def _answer(text: str) -> tuple[str, str]:
    from beastbt.behaviours.ask import choice_of
    qid, sep, value = text.partition("=")
    choice = choice_of(value) if sep else None
    if not qid.strip() or choice is None:
        raise argparse.ArgumentTypeError(f"'{text}' is not ID=yes or ID=no (e.g. --answer door=yes)")
    return qid.strip(), choice


def question_ids(mission: Any) -> list[str]:
    """The ids of the mission's ``ask`` steps (its tasks' included), in document order, each once."""
    from beastbt.mission import steps as st
    from beastbt.mission.warnings import all_steps
    ids: list[str] = []
    for steps in (mission.steps, *mission.tasks.values()):
        for step in all_steps(tuple(steps)):
            if isinstance(step, st.Ask) and step.question_id not in ids:
                ids.append(step.question_id)
    return ids


def unknown_answers(mission: Any, answers: Mapping[str, str]) -> Optional[str]:
    """Why ``--answer`` names a question the mission does not ask (with a hint), or None when all are known.

    An answer to no question would be dropped silently while the real question waits for its timeout.
    """
    import difflib
    ids = question_ids(mission)
    for qid in answers:
        if qid in ids:
            continue
        if not ids:
            return f"--answer {qid}=...: the mission asks no question (it has no 'ask:' step)"
        close = difflib.get_close_matches(qid, ids, n=1)
        hint = f"did you mean '{close[0]}'? " if close else ""
        return (f"--answer {qid}=...: the mission asks no question '{qid}'; {hint}"
                f"its questions: {', '.join(repr(i) for i in ids)}")
    return None


def _map_resolution(text: str) -> float:
    """A map cell size such as ``5 cm`` -> metres (1 mm to 1 m)."""
    from beastbt.mapping.map_files import parse_resolution
    return parse_resolution(text)


def _endpoint(option: str) -> Callable[[str], tuple[str, int]]:
    """``[HOST:]PORT`` of ``option`` -> (host, port); errors name the option."""
    def parse(text: str) -> tuple[str, int]:
        from beastbt.live.endpoint import parse_endpoint
        return parse_endpoint(text, option)
    return parse


def _size(text: str) -> tuple[int, int]:
    from beastbt.live.endpoint import parse_size
    return parse_size(text)


def add_fleet_arguments(p: argparse.ArgumentParser, required: bool = False) -> None:
    """``--fleet ENDPOINT``, ``--fleet-config FILE`` and ``--name NAME`` (``beastbt run`` and ``beastbt serve``)."""
    from beastbt.fleet.config import parse_endpoint
    p.add_argument("--fleet", metavar="ENDPOINT", type=_checked(parse_endpoint),
                   help="report to a fleet's station on Zenoh, e.g. tls/STATION:7447, with the keys of the station's "
                        "enrolment (~/.local/state/beastbt/fleet/robot.json5); the run goes on whatever becomes of "
                        "the link (docs/fleet.md)")
    p.add_argument("--fleet-config", metavar="FILE",
                   help="a standard Zenoh JSON5 configuration for the fleet link (TLS, credentials), such as an "
                        "enrolment's robot.json5")
    p.add_argument("--insecure-loopback", action="store_true",
                   help="join a station that has no keys (its --insecure-loopback): plain TCP on this computer only, "
                        "where any program could command the robot")
    p.add_argument("--name", help="the robot's name on the fleet (default: the profile's 'robot:' name)")


def fleet_options(args: argparse.Namespace, command: str) -> tuple[Optional[Any], Optional[str]]:
    """The run's :class:`~beastbt.fleet.config.FleetOptions` (None without ``--fleet``), or an error message."""
    if args.fleet is None and args.fleet_config is None:
        if args.name is not None:
            return None, f"beastbt {command}: error: --name names the robot on a fleet: add --fleet ENDPOINT"
        return None, None
    from beastbt.fleet.config import FleetOptions
    from beastbt.fleet.keys import name_problem
    if args.name is not None and name_problem(args.name):
        return None, f"beastbt {command}: error: --name: {name_problem(args.name)}"
    from beastbt.fleet.config import INSECURE_ROBOT_WARNING, robot_link
    try:  # safe by default: with keys, or plain TCP on loopback when asked for
        endpoint, config_file = robot_link(args.fleet, args.fleet_config, args.insecure_loopback, command)
    except ValueError as exc:
        return None, f"beastbt {command}: error: {exc}"
    if args.insecure_loopback:
        print(INSECURE_ROBOT_WARNING.format(command=command), file=sys.stderr, flush=True)
    return FleetOptions(endpoint=endpoint, config_file=config_file, name=args.name), None


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``beastbt run``."""
    p.add_argument("mission", help="the mission file (YAML)")
    p.add_argument("--robot", default="sim", help="'sim' (default: the built-in simulator) or a robot profile file")
    p.add_argument("--world", help="simulated world file (default: the mission's 'world:')")
    p.add_argument("--seed", type=_non_negative_int, default=0, help="random seed of the simulator (default 0)")
    p.add_argument("--speed", default="max", help="max (default), realtime, or a factor of real time such as 10")
    p.add_argument("--max-time", type=_positive_duration, help="end the run after this much mission time, e.g. '10 min'")
    p.add_argument("--summary", metavar="FILE", help="write the run summary as JSON to FILE")
    p.add_argument("--record", metavar="FILE", help="also write the run's recording to FILE")
    p.add_argument("--runs-dir", default="runs", help="where run folders go (default: ./runs)")
    p.add_argument("--no-record", action="store_true", help="do not write a run folder")
    p.add_argument("--keep-runs", type=_positive_int, metavar="N",
                   help="keep the newest N finished runs in --runs-dir, pruning older ones as this run starts "
                        "(over the profile's runs: keep; runs marked with 'beastbt runs keep' always stay)")
    p.add_argument("--strict", action="store_true", help="refuse to start when the mission has warnings (exit 2)")
    p.add_argument("--answer", action="append", type=_answer, metavar="ID=yes|no", default=[],
                   help="answer the mission's question ID in advance (repeatable): --answer door=yes")
    p.add_argument("--sim", action="store_true", help="run a real robot profile on the simulator (same geometry and limits)")
    p.add_argument("--files-inside", metavar="DIR",
                   help="read the files the mission names (world, map, route files) only inside DIR, or shipped "
                        "ones by name (the studio's tries use it)")
    p.add_argument("--joystick", metavar="FILE",
                   help="simulator only: play a joystick script (YAML list such as [{at: 2 s, press: enable}, "
                        "{at: 2.5 s, linear: 0.8}, {at: 6 s, release: enable}]) through the real joystick driver")
    p.add_argument("--build-map", metavar="FILE",
                   help="build a map with the LiDAR while the mission (or teleop) runs, and write it when the run "
                        "ends, as a map_server YAML with a PGM beside it, e.g. maps/office.yaml (docs/mapping.md)")
    p.add_argument("--map-resolution", metavar="SIZE", type=_checked(_map_resolution),
                   help="cell size of the --build-map map, e.g. '5 cm' (default)")
    p.add_argument("--console", metavar="[HOST:]PORT", type=_checked(_endpoint("--console")),
                   help="serve the operator console for the run: live video, map, tree, progress, pause/resume/"
                        "abort, e-stop, joystick and questions (page at http://HOST:PORT/); HOST defaults to "
                        "127.0.0.1; off loopback the page needs the token printed at start")
    p.add_argument("--console-token", choices=("auto", "always"), default="auto",
                   help="auto (default): the console needs its token off loopback only; always: on loopback too, "
                        "for a console reached through a reverse proxy or an SSH tunnel (docs/console.md)")
    p.add_argument("--stream", metavar="[HOST:]PORT", type=_checked(_endpoint("--stream")),
                   help="serve the camera live as MJPEG over HTTP (page at http://HOST:PORT/, stream /stream.mjpg); "
                        "HOST defaults to 127.0.0.1")
    p.add_argument("--foxglove", metavar="[HOST:]PORT", type=_checked(_endpoint("--foxglove")),
                   help="serve the run live to Foxglove (open connection: Foxglove WebSocket, ws://HOST:PORT) with "
                        "the recording's channels; 127.0.0.1 unless a host is given, e.g. 0.0.0.0:8765")
    p.add_argument("--stream-size", metavar="WxH", type=_checked(_size), help="size of the streamed frames (default 640x480)")
    p.add_argument("--stream-quality", metavar="Q", type=_quality, help="JPEG quality 1-100 (default 80)")
    p.add_argument("--stream-fps", metavar="FPS", type=_positive_float, help="most frames streamed per second (default 25)")
    p.add_argument("--stream-no-overlay", action="store_true", help="stream the bare camera, without the detected line and step")
    add_fleet_arguments(p)
    from beastbt.ros2.cli import add_ros2_arguments
    add_ros2_arguments(p)
    p.add_argument("--record-images", type=_non_negative_float, metavar="HZ", dest="record_images",
                   help="camera images recorded per second as JPEG (0 for none); without it, 2 per second of a "
                        "camera the run uses anyway, or of any camera with --record-sensors")
    p.add_argument("--record-sensors", action="store_true",
                   help="record every sensor (GPS, IMU, LiDAR, camera images...) even those the run does not read, "
                        "keeping them and the estimator awake; by default a recording holds what the run used and "
                        "where the robot was (GPS fixes, fused pose)")


@reader_safe_stdout
def command(args: argparse.Namespace) -> int:
    """Run the mission; print the summary. 0 success, 1 failure or stopped, 2 invalid input."""
    from beastbt.run.session import RunOptions, parse_speed
    try:
        speed = parse_speed(args.speed)
    except ValueError as exc:
        print(f"beastbt run: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    from beastbt.commands.paths import output_file_problem, output_folder_problem
    from beastbt.mapping.map_files import map_output_problem
    for problem in (output_file_problem("--summary", args.summary), output_file_problem("--record", args.record),
                    map_output_problem("--build-map", args.build_map),
                    None if args.no_record else output_folder_problem("--runs-dir", args.runs_dir)):
        if problem is not None:
            print(f"beastbt run: error: {problem}", file=sys.stderr)
            return EXIT_INVALID
    opts = RunOptions(robot=args.robot, world=args.world, seed=args.seed, speed=speed, max_time_s=args.max_time,
                      summary_path=args.summary, record_path=args.record, runs_dir=args.runs_dir,
                      record=not args.no_record, status_line=sys.stdout.isatty(), simulate=args.sim,
                      joystick_script=args.joystick, stream=args.stream, console=args.console,
                      console_token=args.console_token,
                      foxglove=args.foxglove, stream_size=args.stream_size,
                      stream_quality=args.stream_quality, stream_fps=args.stream_fps,
                      stream_overlay=not args.stream_no_overlay, record_images_hz=args.record_images,
                      record_sensors=args.record_sensors, answers=dict(args.answer), keep_runs=args.keep_runs,
                      files_inside=args.files_inside)
    opts.fleet, problem = fleet_options(args, "run")
    if problem is not None:
        print(problem, file=sys.stderr)
        return EXIT_INVALID
    from beastbt.ros2.cli import ros2_options
    opts.ros2, problem = ros2_options(args, "run")
    if problem is not None:
        print(problem, file=sys.stderr)
        return EXIT_INVALID
    if opts.console_token != "auto" and opts.console is None:
        print(f"beastbt run: error: --console-token {opts.console_token} is for the operator console: add "
              f"--console [HOST:]PORT", file=sys.stderr)
        return EXIT_INVALID
    opts.build_map, opts.map_resolution_m = args.build_map, args.map_resolution
    if opts.map_resolution_m is not None and opts.build_map is None:
        print("beastbt run: error: --map-resolution is the cell size of the map --build-map FILE writes: add "
              "--build-map", file=sys.stderr)
        return EXIT_INVALID
    if opts.joystick_script is not None and not opts.simulated:
        print(f"beastbt run: error: --joystick plays a scripted joystick on the simulator only, and "
              f"--robot {args.robot} is a real robot; add --sim to run its profile on the simulator, or drop "
              f"--joystick to drive with the real gamepad", file=sys.stderr)
        return EXIT_INVALID
    from beastbt.core.errors import InvalidInput
    if isinstance(opts.joystick_script, str):
        from beastbt.sim.joystick_limits import file_size_problem
        too_big = file_size_problem(opts.joystick_script, opts.joystick_script)  # from stat, before reading it
        if too_big is not None:
            print(InvalidInput([too_big]).format(), file=sys.stderr)
            return EXIT_INVALID
    if isinstance(opts.joystick_script, str):
        # The script's YAML (alias bound, numbers) is read before the robot is assembled, so that a hostile script
        # is refused at the cost of reading it, not after the simulator, OpenCV and the parts are imported.
        from beastbt.core.file_refs import JOYSTICK, RefusedFile, read_capped
        from beastbt.sim.joystick_script import script_doc
        try:
            # a regular file within the joystick script's cap: /dev/zero or a pipe is refused, not read
            script_doc(read_capped(opts.joystick_script, JOYSTICK).decode("utf-8"), opts.joystick_script)
        except InvalidInput as exc:
            print(exc.format(), file=sys.stderr)
            return EXIT_INVALID
        except RefusedFile as exc:
            print(f"{opts.joystick_script}:1:1: error: cannot read the joystick script: {exc.message}\n"
                  f"    hint: --joystick takes a YAML file: a list like [{{at: 2 s, press: enable}}]", file=sys.stderr)
            return EXIT_INVALID
        except UnicodeDecodeError:
            pass  # said with its reason when the script is loaded with the robot
    from beastbt.assembly import prepare
    from beastbt.cli import collector_paused
    from beastbt.robot.hardware import DeviceUnavailable
    from beastbt.run.run_folder import RunFolderUnavailable
    from beastbt.run.session import execute
    from beastbt.run.summary import human_summary
    try:
        # Loading, checking and assembling build what lives for the whole run (modules, the tree, the simulator):
        # the cyclic collector is paused while they are built, and back on before anything runs.
        with collector_paused():
            prepared = prepare(args.mission, opts)
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return EXIT_INVALID
    except (DeviceUnavailable, RunFolderUnavailable) as exc:
        print(f"beastbt run: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except KeyboardInterrupt:
        # Ctrl-C while the robot was being built: what was opened is closed by prepare; said, not
        # silent. A run that has started ends itself, stopped, with its summary.
        print("beastbt run: interrupted while the robot was being built: the mission never started, nothing moved",
              file=sys.stderr)
        return EXIT_FAILURE
    unknown = unknown_answers(prepared.mission, opts.answers or {})
    if unknown:
        print(f"beastbt run: error: {unknown}", file=sys.stderr)
        prepared.abandon()
        return EXIT_INVALID
    for problem in prepared.warnings:
        print(problem.format(), file=sys.stderr)
    if args.strict and prepared.warnings:
        n = len(prepared.warnings)
        print(f"beastbt run: error: {n} warning{'' if n == 1 else 's'} and --strict: not started", file=sys.stderr)
        prepared.abandon()
        return EXIT_INVALID
    if args.foxglove is not None:
        host, port = args.foxglove
        print(f"Foxglove live: ws://{host}:{port} (in Foxglove: Open connection -> Foxglove WebSocket; "
              f"layout: beastbt foxglove-layout)", flush=True)
    summary = execute(prepared, sys.stdout)
    print(human_summary(summary))
    if opts.build_map is not None:
        built = summary.get("map") or {}
        if built.get("file"):
            print(f"map written to {built['file']} (image {built['image']}; {built['keyframes']} keyframes, "
                  f"{built['loops_closed']} loop closures)")
        else:
            print(f"beastbt run: no map written to {opts.build_map}: {built.get('error')}", file=sys.stderr)
    return EXIT_SUCCESS if summary["status"] == "success" else EXIT_FAILURE
