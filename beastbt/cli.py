"""The ``beastbt`` command: a static table of subcommands, each imported only when it runs.

``beastbt`` alone prints the overview and exits 2 (a usage error, as argparse
does for a missing subcommand); ``beastbt --version`` prints the version. A
mistyped subcommand or option gets a did-you-mean and exit 2 before anything
starts. ``python -m beastbt`` is the same command.

Exit status: 0 the mission succeeded (or every file is valid), 1 it failed or
was stopped, 2 invalid input (nothing moved).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import importlib
import os
import sys
from types import MappingProxyType
from typing import Iterator, Mapping, NoReturn, Optional, Sequence

EXIT_SUCCESS = 0
EXIT_FAILURE = 1
EXIT_INVALID = 2

PROG = "beastbt"

COMMANDS: Mapping[str, tuple[str, str]] = MappingProxyType({
    "run": ("beastbt.commands.run", "run a mission (on the simulator unless --robot names a profile)"),
    "validate": ("beastbt.commands.validate", "check missions, robot profiles and worlds; errors as FILE:LINE:COLUMN"),
    "test": ("beastbt.commands.test", "run the mission tests (*.test.yaml) on their seeds and faults; one line per "
                                      "test, --junit FILE for CI"),
    "tree": ("beastbt.commands.tree", "print the behaviour tree a mission compiles to (--dot FILE for Graphviz)"),
    "gps": ("beastbt.commands.gps", "GPS tools: decode a recorded NMEA log through the driver (one JSON line per fix)"),
    "report": ("beastbt.commands.report", "summarise a recorded run and draw its plots (report.html)"),
    "replay": ("beastbt.commands.replay", "feed a recorded run back through the estimator and the tree; show differences"),
    "runs": ("beastbt.commands.runs", "list the recorded runs with their outcome, one line each"),
    "export": ("beastbt.commands.export", "export a recorded run: '--ros2 out.mcap' writes a ROS 2 bag (CDR, "
                                          "ros2msg schemas) for ros2 bag play, rviz2 and Foxglove"),
    "recover": ("beastbt.commands.recover", "rewrite a recording cut short (power cut, full disk) as a whole MCAP "
                                            "file, the cut one kept as .cut; rebuild a missing summary"),
    "route": ("beastbt.commands.route", "route tools: 'route from-run RUN' writes the path a recorded run drove "
                                        "as a GPX route (teach and repeat)"),
    "map": ("beastbt.commands.map", "map tools: 'map build RUN --out maps/office.yaml' builds a map_server map from a "
                                    "recorded run's LiDAR scans; 'map show MAP --places MISSION' draws one"),
    "joystick": ("beastbt.commands.joystick", "gamepad tools: 'joystick test' shows its input live, the preset it "
                                              "gets and what each control does"),
    "camera": ("beastbt.commands.camera", "camera tools: 'camera calibrate PHOTOS... --board 9x6 --square 25mm' "
                                          "finds the camera's intrinsics from checkerboard photos"),
    "doctor": ("beastbt.commands.doctor", "check every device of a robot profile (ports, base, GPS, IMU, camera, "
                                          "joystick, CAN) without moving"),
    "studio": ("beastbt.commands.studio", "serve the mission studio: write, place on a map, check and try missions "
                                          "in the browser (docs/studio.md)"),
    "station": ("beastbt.commands.station", "the fleet's station: a Zenoh router for the robots and an HTTP API "
                                            "to list them, command them, send missions and stop them all"),
    "serve": ("beastbt.commands.serve", "a robot on the fleet: wait for missions from the station, run each as "
                                        "'beastbt run' does, and wait again"),
    "service": ("beastbt.commands.service", "run beastbt at boot as a systemd service: 'service install --fleet "
                                            "ENDPOINT' (or --mission FILE), then status, logs, remove"),
    "foxglove-layout": ("beastbt.commands.foxglove_layout", "print a Foxglove layout for recorded and live runs "
                                                            "(beastbt foxglove-layout > beastbt.json, then import it)"),
})
"""Subcommand -> (module with ``add_arguments(parser)`` and ``command(args) -> exit status``, one-line help)."""

LOAD_ONLY = frozenset({"tree", "validate"})
"""Commands that only load, check and print (no run, no server, nothing left open): their process skips the
collector's walk of everything at exit (see :func:`main`)."""


def version() -> str:
    """The installed version of beastbt (the package's own when it is not installed)."""
    try:
        from importlib.metadata import PackageNotFoundError, version as dist_version
        return dist_version("beastbt")
    except PackageNotFoundError:
        from beastbt import __version__
        return __version__


@contextlib.contextmanager
def collector_paused() -> Iterator[None]:
    """Run the block with Python's cyclic garbage collector paused; it is resumed (if it was on) when the block ends.

    Around loading and checking only (``tree``, ``validate``, and ``run`` while it prepares the run): nearly
    everything allocated then is imported code, schemas, the mission and the assembled robot, all kept until the
    process exits, so collecting them while they are built is work thrown away (about a tenth of ``beastbt
    tree``'s start-up). Reference counting still frees what is dropped; only cycles wait for the block's end.
    Never around the running of a mission or a server: the block must end.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


class _VersionAction(argparse.Action):
    """``--version``: print ``beastbt VERSION`` and exit 0, as argparse's ``version`` action does.

    The version is looked up only when asked for: reading the installed package's metadata costs
    every other command tens of milliseconds of start-up.
    """

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS,
                 default: str = argparse.SUPPRESS, help: str = "show program's version number and exit") -> None:
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: Optional[str] = None) -> None:
        parser._print_message(f"{PROG} {version()}\n", sys.stdout)
        parser.exit()


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors say what was expected, with a did-you-mean, and exit 2."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(EXIT_INVALID, f"{self.prog}: error: {message}\n")


def overview_parser() -> argparse.ArgumentParser:
    """The top-level parser: the subcommands with their help, and ``--version``."""
    parser = _Parser(prog=PROG, description="Run YAML missions as behaviour trees on a robot or its simulator.",
                     epilog=f"'{PROG} COMMAND --help' shows a command's options.")
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_, help_text) in COMMANDS.items():
        sub.add_parser(name, help=help_text)
    return parser


def command_parser(name: str) -> tuple[argparse.ArgumentParser, object]:
    """The parser of one subcommand and its module (imported now: only this command's code is loaded)."""
    module_name, help_text = COMMANDS[name]
    module = importlib.import_module(module_name)
    parser = _Parser(prog=f"{PROG} {name}", description=help_text)
    module.add_arguments(parser)  # type: ignore[attr-defined]
    return parser, module


def _first_command(argv: Sequence[str]) -> Optional[int]:
    """The index of the subcommand word in ``argv`` (the first word that is not an option), or None."""
    for i, word in enumerate(argv):
        if not word.startswith("-"):
            return i
    return None


def _unknown_options(parser: argparse.ArgumentParser, unknown: Sequence[str]) -> str:
    """One line naming the unknown options, each with a did-you-mean when one is close."""
    known = [s for action in parser._actions for s in action.option_strings]
    words = []
    for i, word in enumerate(unknown):
        option = word.split("=", 1)[0]
        if not option.startswith("-"):
            if i == 0 or not unknown[i - 1].startswith("-"):  # not the value of the unknown option before it
                words.append(f"unexpected argument '{word}'")
            continue
        import difflib  # only for a mistyped option: it costs every command's start-up otherwise
        close = difflib.get_close_matches(option, known, n=1, cutoff=0.6)
        words.append(f"unknown option '{option}'" + (f"; did you mean '{close[0]}'?" if close else ""))
    return "; ".join(words) + f" (see '{parser.prog} --help')"


def joined_units(args: Sequence[str]) -> list[str]:
    """An option's number and its unit written as two words (``--every 2 m``, ``--max-time 10 min``) made one value
    (``2 m``), as if quoted; anything else is left as it is.

    Only a word that is a unit (or a unit's common spelling, which then gets its did-you-mean) is taken: a file
    called ``m.yaml`` after ``--seed 3`` is still a file.
    """
    from beastbt.core.units import UNIT_SYNONYMS, UNIT_TO_KIND

    def is_number(word: str) -> bool:
        try:
            float(word)
            return True
        except ValueError:
            return False

    out: list[str] = []
    i = 0
    while i < len(args):
        word = args[i]
        out.append(word)
        i += 1
        if not word.startswith("--") or i >= len(args):
            continue
        option, eq, value = word.partition("=")
        number = value if eq else args[i]
        nxt = i if eq else i + 1
        if is_number(number) and nxt < len(args) and (args[nxt] in UNIT_TO_KIND or args[nxt] in UNIT_SYNONYMS):
            if eq:
                out[-1] = f"{option}={number} {args[nxt]}"
                i = nxt + 1
            else:
                out.append(f"{number} {args[nxt]}")
                i = nxt + 1
    return out


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of the ``beastbt`` console script and of ``python -m beastbt``; returns the exit status.

    As a process's entry (``argv`` None), a command that opened a Zenoh session (the fleet, ROS 2) ends the
    process here, without the interpreter's finalization (:mod:`beastbt.core.process_end`)."""
    status = _command_status(argv)
    if argv is None:
        from beastbt.core.process_end import end_process, needs_quick_end
        if needs_quick_end():
            end_process(status)
    return status


def _command_status(argv: Optional[Sequence[str]]) -> int:
    """Parse the command line (``sys.argv`` when ``argv`` is None), run its command; the exit status."""
    args = list(sys.argv[1:] if argv is None else argv)
    # The overview parser (every subcommand's help line) is built only when it is used: a command that is
    # given does not pay for it (a few milliseconds of argparse and gettext lookups).
    at = _first_command(args)
    if at is None:
        top = overview_parser()
        if args:
            top.parse_args(args)  # --help and --version exit here; anything else is an error
        top.print_help()
        return EXIT_INVALID
    name = args[at]
    if name not in COMMANDS:
        import difflib  # only for a mistyped command
        close = difflib.get_close_matches(name, list(COMMANDS), n=1, cutoff=0.5)
        hint = f"; did you mean '{close[0]}'?" if close else f"; the commands are: {', '.join(COMMANDS)}"
        overview_parser().print_usage(sys.stderr)
        print(f"{PROG}: error: unknown command '{name}'{hint}", file=sys.stderr)
        return EXIT_INVALID
    if at:
        overview_parser().parse_args(args[:at])  # options before the command: --help, --version, or an error
    parser, module = command_parser(name)
    parsed, unknown = parser.parse_known_args(joined_units(args[at + 1:]))
    if unknown:
        parser.error(_unknown_options(parser, unknown))
    try:
        status = int(module.command(parsed))  # type: ignore[attr-defined]
        if argv is None and name in LOAD_ONLY:
            # The process ends now. Python's last act would be a full collection walking every object the
            # command loaded (about a tenth of 'beastbt tree'); they are all kept to the end, and the system
            # frees the memory at exit. Frozen, the collector leaves them be. (Not when main() is called with
            # arguments, as the tests do: that process goes on.)
            gc.freeze()
        return status
    except KeyboardInterrupt:
        return EXIT_FAILURE
    except BrokenPipeError:
        # The reader went away (``beastbt tree m.yaml | head``): not an error of ours; say nothing more.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_SUCCESS
    except Exception as exc:  # noqa: BLE001 - the last resort: a clear answer, the details kept in a file
        return _internal_error(name, exc)


def _internal_error(command: str, exc: BaseException) -> int:
    """Say that beastbt itself failed, in one line and a hint, and keep the traceback in a file; returns 1.

    The robot is already stopped by then (a run's end, whatever ends it, sends a stop, and the base's own
    heartbeat stops it if nothing does). ``BEASTBT_TRACEBACK=1`` prints the traceback as well.
    """
    import tempfile
    import traceback

    text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    where = ""
    try:
        fd, path = tempfile.mkstemp(prefix=f"beastbt-{command}-crash-", suffix=".txt")
        with os.fdopen(fd, "w", encoding="utf-8") as out:
            out.write(text)
        where = f"; the details are in {path}"
    except OSError:
        pass
    if os.environ.get("BEASTBT_TRACEBACK") == "1":
        print(text, file=sys.stderr, end="")
    message = str(exc).splitlines()[0][:300] if str(exc) else ""
    print(f"{PROG}: internal error in '{command}': {type(exc).__name__}: {message}{where}", file=sys.stderr)
    print("    hint: this is a fault of beastbt, not of your files: please report it with that file", file=sys.stderr)
    return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
