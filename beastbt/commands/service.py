"""``beastbt service install|status|logs|remove``: beastbt as a systemd service that starts at boot.

``install`` writes ``/etc/systemd/system/NAME.service`` (or into ``--root DIR`` for tests and image builders)
that runs ``beastbt serve`` (a robot that joins the station and waits for missions) or, with ``--mission FILE``,
one mission, as the invoking user, with:

- ``Type=notify`` and ``WatchdogSec=``: the tick loop feeds systemd's watchdog every tick
  (:mod:`beastbt.run.sd_notify`), so a hung loop is killed and restarted;
- ``Restart=on-failure``: a crash or a watchdog kill is restarted (a mission that fails, exit 1, or an invalid
  one, exit 2, is not run again and again);
- the groups the devices need (serial ``dialout``, ``i2c``, ``video``, ``gpio``, ``input``), those the system has;
- output to journald (``service logs``).

Then, without ``--root``, it reloads systemd and enables and starts the unit. ``status``, ``logs`` and ``remove``
ask ``systemctl`` and ``journalctl``. Exit status: 0 done, 1 a systemd tool failed, 2 invalid input.
"""

from __future__ import annotations

import argparse
import os
import pwd
import grp
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Optional, Sequence

EXIT_SUCCESS, EXIT_FAILURE, EXIT_INVALID = 0, 1, 2
DEFAULT_NAME = "beastbt"
"""The unit's name (``beastbt.service``)."""
DEVICE_GROUPS = ("dialout", "i2c", "video", "gpio", "input")
"""Groups whose members may open the serial ports, the I2C bus, the camera, the GPIO pins and the gamepad."""
DEFAULT_WATCHDOG_S = 10
"""``WatchdogSec=`` (s): no tick for this long and systemd restarts beastbt. Far above a tick (20-50 ms) and the
longest start-up step, far below what a person notices as a dead robot."""
UNIT_DIR = "etc/systemd/system"
"""Where units of the local administrator live, below the root."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The actions of ``beastbt service`` and their options."""
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    install = sub.add_parser("install", help="write the unit (and, without --root, enable and start it)",
                             description="Write a systemd unit that runs 'beastbt serve' (or one mission) at boot. "
                                         "Arguments after '--' are passed on to the command as they are.")
    install.add_argument("--robot", default="sim", help="the robot profile (default: sim)")
    install.add_argument("--sim", action="store_true", help="run the profile on the simulator")
    install.add_argument("--mission", metavar="FILE", help="run this mission at boot instead of serving the fleet")
    install.add_argument("--fleet", metavar="ENDPOINT", help="the station to join (serve), e.g. tls/station:7447")
    install.add_argument("--fleet-config", metavar="FILE", help="the robot's fleet configuration (serve)")
    install.add_argument("--runs-dir", metavar="DIR", help="where run folders go (default: runs/ in --workdir)")
    install.add_argument("--workdir", metavar="DIR", help="the service's working folder (default: this folder)")
    install.add_argument("--user", help="the user it runs as (default: the one who called sudo, else you)")
    install.add_argument("--watchdog", type=int, default=DEFAULT_WATCHDOG_S, metavar="S",
                         help=f"restart when the loop has not ticked for S seconds (default {DEFAULT_WATCHDOG_S})")
    install.add_argument("--no-start", action="store_true", help="write and enable, but do not start it now")
    install.add_argument("extra", nargs=argparse.REMAINDER, help="after '--': more options for 'serve' or 'run'")
    for name, text in (("status", "is it running, and its last lines"), ("logs", "its journal"),
                       ("remove", "stop, disable and delete the unit")):
        action = sub.add_parser(name, help=text)
        if name == "logs":
            action.add_argument("-f", "--follow", action="store_true", help="keep printing new lines")
            action.add_argument("-n", "--lines", type=int, default=200, help="how many lines (default 200)")
    for action in sub.choices.values():
        action.add_argument("--name", default=DEFAULT_NAME, help=f"the unit's name (default {DEFAULT_NAME})")
        action.add_argument("--root", metavar="DIR",
                            help="write into (or remove from) this root instead of / and call no systemd tool")


def command(args: argparse.Namespace) -> int:
    """Run one service action."""
    if not _valid_name(args.name):
        print(f"beastbt service: error: --name {args.name!r}: letters, digits, '-', '_' and '.' only",
              file=sys.stderr)
        return EXIT_INVALID
    return {"install": install, "status": status, "logs": logs, "remove": remove}[args.action](args)


def _valid_name(name: str) -> bool:
    return bool(name) and all(c.isalnum() or c in "-_." for c in name) and not name.startswith(".")


def unit_path(root: Optional[str], name: str) -> Path:
    """Where the unit file goes: ``ROOT/etc/systemd/system/NAME.service``."""
    return Path(root or "/") / UNIT_DIR / f"{name}.service"


def invoking_user() -> str:
    """The user the service runs as by default: who called ``sudo``, else whoever runs this."""
    return os.environ.get("SUDO_USER") or pwd.getpwuid(os.getuid()).pw_name


def existing_groups(root: Optional[str]) -> set[str]:
    """The group names the target system has (its ``/etc/group`` below ``root``, else this machine's)."""
    group_file = Path(root or "/") / "etc" / "group"
    if root and group_file.is_file():
        return {line.split(":", 1)[0] for line in group_file.read_text(encoding="utf-8").splitlines() if line}
    return {g.gr_name for g in grp.getgrall()}


def exec_start(args: argparse.Namespace, python: str = sys.executable) -> list[str]:
    """The command line the unit runs: this Python's ``-m beastbt serve`` or ``run MISSION``, with the options."""
    extra = list(args.extra or [])
    if extra[:1] == ["--"]:
        extra = extra[1:]
    command = [python, "-m", "beastbt"]
    if args.mission:
        command += ["run", str(Path(args.mission).resolve()), "--robot", args.robot]
    else:
        command += ["serve", "--robot", args.robot]
        if args.fleet:
            command += ["--fleet", args.fleet]
        if args.fleet_config:
            command += ["--fleet-config", str(Path(args.fleet_config).resolve())]
    if args.sim:
        command.append("--sim")
    if args.runs_dir:
        command += ["--runs-dir", str(Path(args.runs_dir).resolve())]
    return command + extra


def unit_text(args: argparse.Namespace, user: str, groups: Sequence[str], workdir: Path,
              command: Sequence[str]) -> str:
    """The unit file's text (systemd.service(5)); every line commented where its reason is not plain."""
    what = f"mission {Path(args.mission).name}" if args.mission else "serve the fleet"
    one_shot_exits = "RestartPreventExitStatus=1 2\n" if args.mission else "RestartPreventExitStatus=2\n"
    return (
        "# Written by 'beastbt service install'; 'beastbt service remove' takes it away.\n"
        "[Unit]\n"
        f"Description=beastbt on robot {args.robot}: {what}\n"
        "Wants=network-online.target\n"
        "After=network-online.target\n"
        "# Five crashes within two minutes and systemd stops trying (see 'beastbt service status').\n"
        "StartLimitIntervalSec=120\n"
        "StartLimitBurst=5\n"
        "\n"
        "[Service]\n"
        "Type=notify\n"
        "NotifyAccess=main\n"
        f"User={user}\n"
        + (f"SupplementaryGroups={' '.join(groups)}\n" if groups else "")
        + f"WorkingDirectory={workdir}\n"
        f"ExecStart={' '.join(_quote(part) for part in command)}\n"
        "# The tick loop feeds the watchdog every tick; silent this long, the process is killed and restarted.\n"
        f"WatchdogSec={args.watchdog}\n"
        "Restart=on-failure\n"
        "RestartSec=2\n"
        "# Exit 2 is invalid input: restarting would not mend it."
        + (" A mission run once that failed (exit 1) is not re-run." if args.mission else "") + "\n"
        + one_shot_exits
        + "# SIGTERM stops the robot, closes the recording and writes the summary, as Ctrl-C does.\n"
        "KillSignal=SIGTERM\n"
        "TimeoutStopSec=15\n"
        "StandardOutput=journal\n"
        "StandardError=journal\n"
        f"SyslogIdentifier={args.name}\n"
        "Environment=PYTHONUNBUFFERED=1\n"
        "\n"
        "[Install]\n"
        "WantedBy=multi-user.target\n"
    )


def _quote(part: str) -> str:
    """One ExecStart word, quoted as systemd reads it (double quotes, backslash escapes) when it needs to be."""
    if part and all(c.isalnum() or c in "-_./:=@+," for c in part):
        return part
    return '"' + part.replace("\\", "\\\\").replace('"', '\\"') + '"'


def install(args: argparse.Namespace) -> int:
    """Write the unit; without ``--root``: reload systemd, enable it, and start it (unless ``--no-start``)."""
    if args.mission and (args.fleet or args.fleet_config):
        print("beastbt service install: error: --mission runs one mission; --fleet and --fleet-config are for "
              "serving the station's missions: give one or the other", file=sys.stderr)
        return EXIT_INVALID
    if not args.mission and not (args.fleet or args.fleet_config):
        print("beastbt service install: error: say what to run: --fleet ENDPOINT (or --fleet-config FILE) to "
              "serve the station, or --mission FILE", file=sys.stderr)
        return EXIT_INVALID
    if args.mission and not Path(args.mission).is_file():
        print(f"beastbt service install: error: --mission {args.mission}: no such file", file=sys.stderr)
        return EXIT_INVALID
    if args.watchdog < 1:
        print("beastbt service install: error: --watchdog takes whole seconds, at least 1", file=sys.stderr)
        return EXIT_INVALID
    user = args.user or invoking_user()
    if args.root is None:
        try:
            pwd.getpwnam(user)
        except KeyError:
            print(f"beastbt service install: error: --user {user}: no such user here", file=sys.stderr)
            return EXIT_INVALID
    have = existing_groups(args.root)
    groups = [g for g in DEVICE_GROUPS if g in have]
    missing = [g for g in DEVICE_GROUPS if g not in have]
    workdir = Path(args.workdir or os.getcwd()).resolve()
    command = exec_start(args)
    path = unit_path(args.root, args.name)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(unit_text(args, user, groups, workdir, command), encoding="utf-8")
    except PermissionError:
        print(f"beastbt service install: error: cannot write {path}: run it with sudo (the service still runs "
              f"as {user})", file=sys.stderr)
        return EXIT_INVALID
    print(f"wrote {path}: runs {' '.join(command[2:])} as {user}" + (f" (groups {', '.join(groups)})" if groups
                                                                      else ""))
    if missing:
        print(f"  note: this system has no group {', '.join(missing)}; the unit leaves it out")
    if args.root is not None:
        return EXIT_SUCCESS
    steps = [["systemctl", "daemon-reload"], ["systemctl", "enable", f"{args.name}.service"]]
    if not args.no_start:
        steps.append(["systemctl", "restart", f"{args.name}.service"])
    for step in steps:
        if _systemd(step) != 0:
            return EXIT_FAILURE
    print(f"enabled: it starts at boot. 'beastbt service status' shows it, 'beastbt service logs -f' follows it.")
    return EXIT_SUCCESS


def status(args: argparse.Namespace) -> int:
    """``systemctl status``: running or not, since when, the last lines of its journal."""
    if args.root is not None:
        path = unit_path(args.root, args.name)
        print(f"{path}: {'installed' if path.is_file() else 'not installed'} (no systemd is asked with --root)")
        return EXIT_SUCCESS if path.is_file() else EXIT_FAILURE
    return _systemd(["systemctl", "status", "--no-pager", f"{args.name}.service"], quiet_ok=(3,))


def logs(args: argparse.Namespace) -> int:
    """``journalctl -u NAME``: the service's output, newest last (``-f`` to follow)."""
    if args.root is not None:
        print("beastbt service logs: error: --root has no journal to read", file=sys.stderr)
        return EXIT_INVALID
    command = ["journalctl", "--no-pager", "-u", f"{args.name}.service", "-n", str(args.lines)]
    return _systemd(command + (["-f"] if args.follow else []))


def remove(args: argparse.Namespace) -> int:
    """Stop and disable the service, delete its unit and reload systemd (``--root``: only delete the file)."""
    path = unit_path(args.root, args.name)
    if args.root is None and path.is_file():
        _systemd(["systemctl", "disable", "--now", f"{args.name}.service"])
    if not path.is_file():
        print(f"beastbt service remove: {path} is not there: nothing to remove")
        return EXIT_SUCCESS
    try:
        path.unlink()
    except PermissionError:
        print(f"beastbt service remove: error: cannot delete {path}: run it with sudo", file=sys.stderr)
        return EXIT_INVALID
    print(f"removed {path}")
    if args.root is None:
        _systemd(["systemctl", "daemon-reload"])
    return EXIT_SUCCESS


def _systemd(command: list[str], quiet_ok: tuple[int, ...] = ()) -> int:
    """Run a systemd tool, its output straight to the terminal; a missing tool or a failure is said in words."""
    if shutil.which(command[0]) is None:
        print(f"beastbt service: error: {command[0]} is not here: this system does not run systemd "
              f"(write the unit elsewhere with --root DIR)", file=sys.stderr)
        return EXIT_FAILURE
    done = subprocess.run(command)
    if done.returncode != 0 and done.returncode not in quiet_ok:
        print(f"beastbt service: {shlex.join(command)} failed (exit {done.returncode})", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_SUCCESS if done.returncode == 0 else done.returncode
