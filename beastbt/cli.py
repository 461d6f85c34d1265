"""The ``beastbt`` command: run, validate and inspect missions.

Exit status: 0 the mission succeeded (or every file is valid), 1 it failed or
was stopped, 2 invalid input (nothing moved).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Any, Callable, Optional, Sequence

from beastbt.core.errors import InvalidInput
from beastbt.core.units import UnitError, parse_duration

EXIT_SUCCESS = 0
EXIT_FAILURE = 1
EXIT_INVALID = 2


def _duration(text: str) -> float:
    try:
        return parse_duration(text)
    except UnitError as exc:
        raise argparse.ArgumentTypeError(str(exc))


def _add_run(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", help="the mission file (YAML)")
    p.add_argument("--robot", default="sim", help="'sim' (default: the built-in simulator) or a robot profile file")
    p.add_argument("--world", help="simulated world file (default: the mission's 'world:')")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulator (default 0)")
    p.add_argument("--speed", default="max", help="max (default), realtime, or a factor of real time such as 10")
    p.add_argument("--max-time", type=_duration, help="end the run after this much mission time, e.g. '10 min'")
    p.add_argument("--summary", metavar="FILE", help="write the run summary as JSON to FILE")
    p.add_argument("--record", metavar="FILE", help="also write the run's recording to FILE")
    p.add_argument("--runs-dir", default="runs", help="where run folders go (default: ./runs)")
    p.add_argument("--no-record", action="store_true", help="do not write a run folder")
    p.add_argument("--sim", action="store_true", help="run a real robot profile on the simulator (same geometry and limits)")
    p.add_argument("--joystick", metavar="FILE",
                   help="simulator only: play a joystick script (YAML list such as [{at: 2 s, press: enable}, "
                        "{at: 2.5 s, linear: 0.8}, {at: 6 s, release: enable}]) through the real joystick driver")
    p.add_argument("--stream", metavar="[HOST:]PORT", type=_checked(_parse_endpoint),
                   help="serve the camera live as MJPEG over HTTP (page at http://HOST:PORT/, stream /stream.mjpg); "
                        "HOST defaults to 127.0.0.1")
    p.add_argument("--stream-size", metavar="WxH", type=_checked(_parse_size), help="size of the streamed frames (default 640x480)")
    p.add_argument("--stream-quality", metavar="Q", type=int, help="JPEG quality 1-100 (default 80)")
    p.add_argument("--stream-fps", metavar="FPS", type=float, help="most frames streamed per second (default 25)")
    p.add_argument("--stream-no-overlay", action="store_true", help="stream the bare camera, without the detected line and step")
    p.add_argument("--record-images", type=float, metavar="HZ", dest="record_images",
                   help="camera images recorded per second as JPEG (default 2; 0 for none)")


def _parse_endpoint(text: str) -> tuple[str, int]:
    from beastbt.live.endpoint import parse_endpoint
    return parse_endpoint(text)


def _parse_size(text: str) -> tuple[int, int]:
    from beastbt.live.endpoint import parse_size
    return parse_size(text)


def _checked(parse: Callable[[str], Any]) -> Callable[[str], Any]:
    def convert(text: str) -> Any:
        try:
            return parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc))
    return convert


def _cmd_run(args: argparse.Namespace) -> int:
    from beastbt.assembly import prepare
    from beastbt.robot.hardware import DeviceUnavailable
    from beastbt.run.session import RunOptions, execute, parse_speed
    from beastbt.run.summary import human_summary
    try:
        speed = parse_speed(args.speed)
    except ValueError as exc:
        print(f"beastbt run: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    opts = RunOptions(robot=args.robot, world=args.world, seed=args.seed, speed=speed, max_time_s=args.max_time,
                      summary_path=args.summary, record_path=args.record, runs_dir=args.runs_dir,
                      record=not args.no_record, status_line=sys.stdout.isatty(), simulate=args.sim,
                      joystick_script=args.joystick, stream=args.stream, stream_size=args.stream_size,
                      stream_quality=args.stream_quality, stream_fps=args.stream_fps,
                      stream_overlay=not args.stream_no_overlay, record_images_hz=args.record_images)
    try:
        prepared = prepare(args.mission, opts)
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return EXIT_INVALID
    except DeviceUnavailable as exc:
        print(f"beastbt run: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    summary = execute(prepared, sys.stdout)
    print(human_summary(summary))
    return EXIT_SUCCESS if summary["status"] == "success" else EXIT_FAILURE


def _add_validate(p: argparse.ArgumentParser) -> None:
    p.add_argument("files", nargs="+", help="mission files (or robot profiles / worlds, recognised by their first key)")


def _cmd_validate(args: argparse.Namespace) -> int:
    from beastbt.validate import validate_file
    bad = 0
    for f in args.files:
        problems = validate_file(f)
        if problems:
            bad += 1
            for p in problems:
                print(p.format(), file=sys.stderr)
        else:
            print(f"{f}: ok")
    return EXIT_INVALID if bad else EXIT_SUCCESS


def _add_tree(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", help="the mission file (YAML)")
    p.add_argument("--robot", default="sim", help="robot profile the tree is compiled for (default: sim)")
    p.add_argument("--dot", metavar="FILE", help="also write the tree as Graphviz DOT to FILE")


def _cmd_tree(args: argparse.Namespace) -> int:
    import py_trees

    from beastbt.assembly import prepare
    from beastbt.mission.compile import tree_to_dot
    from beastbt.run.session import RunOptions
    try:
        prepared = prepare(args.mission, RunOptions(robot=args.robot, record=False))
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return EXIT_INVALID
    root = prepared.run.root
    print(py_trees.display.unicode_tree(root))
    if args.dot:
        with open(args.dot, "w", encoding="utf-8") as f:
            f.write(tree_to_dot(root))
        print(f"wrote {args.dot}")
    prepared.run.io.close()
    return EXIT_SUCCESS


LAZY_COMMANDS: dict[str, tuple[str, str]] = {
    "gps": ("beastbt.commands.gps", "GPS tools: decode a recorded NMEA log through the driver (one JSON line per fix)"),
    "report": ("beastbt.recording.report", "summarise a recorded run and draw its plots"),
    "replay": ("beastbt.replay", "replay a recorded run through the estimator and the tree; show where the commands differ"),
    "runs": ("beastbt.recording.runs_list", "list the recorded runs"),
}
"""Subcommands whose code lives elsewhere: name -> (module with add_arguments and command, help)."""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``beastbt`` command."""
    parser = argparse.ArgumentParser(prog="beastbt", description="Run YAML missions as behaviour trees on a robot or its simulator.")
    sub = parser.add_subparsers(dest="command", required=True)
    builtin = {
        "run": (_add_run, _cmd_run, "run a mission (on the simulator unless --robot names a profile)"),
        "validate": (_add_validate, _cmd_validate, "check mission files; errors as FILE:LINE:COLUMN"),
        "tree": (_add_tree, _cmd_tree, "print the behaviour tree a mission compiles to"),
    }
    for name, (add, handler, help_text) in builtin.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        add(p)
        p.set_defaults(func=handler)
    for name, (target, help_text) in LAZY_COMMANDS.items():
        module = importlib.import_module(target)
        p = sub.add_parser(name, help=help_text, description=help_text)
        module.add_arguments(p)
        p.set_defaults(func=module.command)
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of the ``beastbt`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
