"""``beastbt station``: the fleet's station, a Zenoh router and an HTTP API for every robot on it (docs/fleet.md).

Safe by default: without ``--fleet-config`` the station makes the fleet's
keys itself on its first start (a CA, its certificate, the robots', in the
per-user fleet folder or ``--keys DIR``), listens for mutual TLS only, with
Zenoh's access control (only the station commands), and prints what a robot
needs to join (its enrolment). Plain TCP is an explicit opt-out,
``--insecure-loopback``: on loopback only, with a loud warning.

Exit status: 0 when stopped (Ctrl-C, SIGTERM), 2 when it cannot start (an
address it cannot listen on, a bad ``--fleet-config``, plain TCP beyond loopback).
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path
from typing import Any, Optional

EXIT_SUCCESS, EXIT_FAILURE, EXIT_INVALID = 0, 1, 2
DEFAULT_LISTEN = "tls/127.0.0.1:7447"
"""Where robots connect by default: this computer only, mutual TLS."""
INSECURE_LISTEN = "tcp/127.0.0.1:7447"
"""Where robots connect with ``--insecure-loopback``: plain TCP, this computer only."""
DEFAULT_CONSOLE = "127.0.0.1:8090"
INSECURE_WARNING = """beastbt station: WARNING: --insecure-loopback: the fleet link is plain TCP, with no keys.
    Any program of any user of this computer can command every robot (send missions, pause, abort,
    latch and reset the e-stop) and pose as a robot on the station's page. For a bench only: without
    --insecure-loopback the station makes the fleet's keys and robots join with mutual TLS."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``beastbt station``."""
    p.add_argument("--listen", default=None, metavar="ENDPOINT",
                   help=f"where robots connect (Zenoh endpoint, default {DEFAULT_LISTEN}: this computer only; "
                        f"tls/0.0.0.0:7447 for every network); mutual TLS with the fleet's keys, made on the "
                        f"first start")
    p.add_argument("--console", default=DEFAULT_CONSOLE, metavar="[HOST:]PORT",
                   help=f"where the station's page and HTTP API listen (default {DEFAULT_CONSOLE}); off loopback "
                        f"they need the token printed at start")
    p.add_argument("--console-token", choices=("auto", "always"), default="auto",
                   help="auto (default): the token is needed off loopback only; always: on loopback too")
    p.add_argument("--fleet-config", metavar="FILE", help="a standard Zenoh JSON5 configuration for the router "
                                                          "(TLS, credentials, access control), instead of the "
                                                          "station's own keys")
    p.add_argument("--keys", metavar="DIR", help="the fleet's keys: made there on the first start, with each "
                                                 "robot's enrolment (default: the per-user folder, "
                                                 "~/.local/state/beastbt/fleet)")
    p.add_argument("--insecure-loopback", action="store_true",
                   help=f"no keys: plain TCP on this computer only (default {INSECURE_LISTEN}), where any program "
                        f"of any user can command the robots; refused beyond loopback")
    p.add_argument("--simulate", type=int, default=0, metavar="N",
                   help="also start N simulated robots (sim-1 ... sim-N, each a 'beastbt serve --sim') side by side")
    p.add_argument("--world", help="with --simulate: the world they share (default: an empty plain)")
    p.add_argument("--speed", default="realtime", help="with --simulate: realtime (default), max or a factor")
    p.add_argument("--runs-dir", default="runs", help="with --simulate: where their run folders go (default ./runs)")
    p.add_argument("--init-keys", metavar="DIR", help="write a fleet's CA, the station's and the robots' "
                                                      "certificates, DIR/station.json5 and DIR/robot.json5 (mutual "
                                                      "TLS, only the station commands) and a how-to; then exit")
    p.add_argument("--robot-name", action="append", default=[], metavar="NAME",
                   help="give robot NAME a certificate of its own (when the keys are made, or added to them later), "
                        "with which it may use only its own keys (repeatable); without it, one certificate for every "
                        "robot")
    p.add_argument("--host", action="append", default=[], metavar="NAME",
                   help="a name or address robots reach the station by, that its certificate must be valid for "
                        "(repeatable; localhost, 127.0.0.1 and this computer's name always)")


def command(args: argparse.Namespace) -> int:
    """Run the station until Ctrl-C or SIGTERM (or, with ``--init-keys``, write the keys and exit)."""
    if args.init_keys:
        return init_keys(args)
    from beastbt.core.errors import InvalidInput
    from beastbt.fleet.config import is_plain, parse_endpoint, plain_problem
    from beastbt.live.endpoint import parse_endpoint as parse_http
    try:
        listen = parse_endpoint(listen_text(args), "--listen")
        host, port = parse_http(args.console, "--console")
        if args.insecure_loopback:
            if args.fleet_config:
                raise ValueError("--insecure-loopback is for a fleet without keys: drop it (--fleet-config has them)")
            if not is_plain(listen):
                raise ValueError(f"--insecure-loopback listens on plain tcp/127.0.0.1:PORT, not {listen}")
            problem = plain_problem(listen, "--listen")
            if problem:
                raise ValueError(f"--insecure-loopback: {problem}")
        elif not args.fleet_config and is_plain(listen):
            raise ValueError(f"--listen {listen}: the fleet link is mutual TLS with the station's keys: listen on "
                             f"tls/HOST:PORT (e.g. {DEFAULT_LISTEN}); plain TCP is --insecure-loopback, on this "
                             f"computer only")
    except ValueError as exc:
        print(f"beastbt station: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    if args.simulate < 0:
        print("beastbt station: error: --simulate N takes N >= 0", file=sys.stderr)
        return EXIT_INVALID
    config_file, robot_config = args.fleet_config, None
    if args.insecure_loopback:
        print(INSECURE_WARNING, file=sys.stderr, flush=True)
    elif not config_file:
        keys = station_keys(args, listen)
        if keys is None:
            return EXIT_INVALID
        config_file, robot_config = keys
    elif args.simulate:
        beside = Path(config_file).parent / "robot.json5"  # the keys of --init-keys: the robots' beside the station's
        robot_config = str(beside) if beside.is_file() else None
    if args.simulate and not args.insecure_loopback and robot_config is None:
        print("beastbt station: error: --simulate N: the simulated robots join with the robots' shared keys "
              "(robot.json5), and there are none here: made with --robot-name, each robot has its own",
              file=sys.stderr)
        return EXIT_INVALID
    if args.world:
        from beastbt.core.errors import InvalidInput as Invalid
        from beastbt.sim.world import load_world
        try:
            load_world(args.world)
        except Invalid as exc:
            print(exc.format(), file=sys.stderr)
            return EXIT_INVALID
    from beastbt.fleet.station import Station, StationServer
    from beastbt.live.endpoint import is_loopback
    station = Station(listen, config_file)
    try:
        station.open()
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return EXIT_INVALID
    except Exception as exc:  # noqa: BLE001 - zenoh's own error: say it in one line
        print(f"beastbt station: error: cannot open the fleet's router on {listen}: {str(exc).splitlines()[0][:300]}",
              file=sys.stderr)
        print("    hint: is another station listening there? pick another port with --listen", file=sys.stderr)
        return EXIT_INVALID
    server = StationServer(station, host, port,
                           require_token=True if args.console_token == "always" else not is_loopback(host))
    try:
        server.start()
    except OSError as exc:
        station.close()
        print(f"beastbt station: error: --console: cannot listen on {host}:{port}: {exc.strerror or exc}",
              file=sys.stderr)
        return EXIT_INVALID
    print(f"fleet station: robots connect to {listen}", flush=True)
    if args.insecure_loopback:
        print("fleet station: plain TCP, no keys: robots join with 'beastbt serve --insecure-loopback --fleet "
              f"{listen}'", flush=True)
    print(f"station page and API: {server.url}", flush=True)
    simulated = []
    if args.simulate > 0:
        import tempfile

        from beastbt.fleet.simulate import start_robots
        worlds = Path(tempfile.mkdtemp(prefix="beastbt-simulate-"))
        link = ["--insecure-loopback"] if args.insecure_loopback else ["--fleet-config", str(robot_config)]
        simulated = start_robots(args.simulate, args.world, local_endpoint(listen), args.speed, worlds,
                                 args.runs_dir, link)
        print(f"{args.simulate} simulated robots: sim-1 ... sim-{args.simulate}", flush=True)
    done = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: done.set())
    try:
        while not done.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        for proc in simulated:
            proc.terminate()
        for proc in simulated:
            try:
                proc.wait(10)
            except Exception:  # noqa: BLE001 - one that does not end is killed
                proc.kill()
        server.close()
        station.close()
    return EXIT_SUCCESS


def listen_text(args: argparse.Namespace) -> str:
    """The ``--listen`` asked for, or the default of the mode; ``HOST:PORT`` and ``PORT`` are TLS with keys."""
    if args.listen is None:
        return INSECURE_LISTEN if args.insecure_loopback else DEFAULT_LISTEN
    text = str(args.listen).strip()
    if "/" not in text and not args.insecure_loopback and not args.fleet_config:
        text = "tls/" + (f"127.0.0.1:{text}" if text.isdigit() else text)
    return text


def local_endpoint(listen: str) -> str:
    """Where a robot on this computer reaches a station listening on ``listen``."""
    return listen.replace("0.0.0.0", "127.0.0.1").replace("[::]", "127.0.0.1")


def station_keys(args: argparse.Namespace, listen: str) -> "tuple[str, Optional[str]] | None":
    """The station's keys (made on the first start, in ``--keys`` or the per-user folder), with the robot's
    enrolment printed: (the station's configuration, the robots' shared one or None); None when they cannot be
    made (said on standard error)."""
    import shutil
    import socket
    import subprocess

    from beastbt.fleet.config import endpoint_host, fleet_folder
    from beastbt.fleet.credentials import ensure_keys
    if shutil.which("openssl") is None:
        print("beastbt station: error: the fleet's keys are made with the openssl command (apt install openssl); "
              "or give --fleet-config FILE", file=sys.stderr)
        return None
    folder = Path(args.keys).expanduser() if args.keys else fleet_folder()
    bad = [h for h in args.host if not _host_ok(h)]
    if bad:
        print(f"beastbt station: error: --host {bad[0][:80]!r}: a name or an address robots reach the station by "
              f"(letters, digits, '.', '-', ':'), e.g. --host station.local or --host 192.168.1.10", file=sys.stderr)
        return None
    hosts = [socket.gethostname(), f"{socket.gethostname()}.local", *args.host]
    bound = endpoint_host(listen)
    if bound not in ("0.0.0.0", "::", ""):
        hosts.append(bound)  # robots reach it there: the certificate must say so
    try:
        problem = _robot_names_problem(args.robot_name)
        if problem:
            raise ValueError(problem)
        state = ensure_keys(folder, [h for h in hosts if _host_ok(h)], listen, args.robot_name)
    except (ValueError, FileExistsError, OSError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or str(exc)
        print(f"beastbt station: error: the fleet's keys in {folder}: {str(detail).strip()[:300]}", file=sys.stderr)
        return None
    print(enrolment(folder.resolve(), listen, state, default=not args.keys), end="", flush=True)
    shared = folder / "robot.json5"
    return str(folder / "station.json5"), str(shared) if shared.is_file() else None


def _host_ok(host: str) -> bool:
    import re
    return bool(re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9.:-]{0,252}", host))


def _robot_names_problem(names: list) -> Optional[str]:
    from beastbt.fleet.keys import name_problem
    for name in names:
        problem = name_problem(name) or ("'station' is the station's own name" if name == "station" else None)
        if problem:
            return f"--robot-name {name[:80]}: {problem}"
    return None


def enrolment(folder: Path, listen: str, state: Any, default: bool = True) -> str:
    """What the station prints at start: where its keys are, the names its certificate holds, and how a robot joins
    (its enrolment folder, copied to it, and the command to run there)."""
    from beastbt.fleet.config import DEFAULT_PORT, endpoint_host
    from beastbt.fleet.credentials import enrolments, station_names
    port = listen.rsplit(":", 1)[-1] or DEFAULT_PORT
    names = station_names(folder)
    lines = [f"fleet keys: {folder} ({'made now' if state.made else 'kept'}): mutual TLS only, and only this station "
             f"commands the robots (keep ca.key on this computer)"]
    if state.hosts_added:
        lines.append(f"the station's certificate was made again for {', '.join(state.hosts_added)} (the robots keep "
                     f"theirs)")
    if state.robots_added:
        lines.append(f"a certificate of its own for {', '.join(state.robots_added)}: enrol it as below")
    lines.append(f"the station's certificate is valid for: {', '.join(names)} (another one: --host NAME)")
    if endpoint_host(listen) in ("127.0.0.1", "::1", "localhost"):
        lines.append("listening on this computer only: for robots on the network, --listen tls/0.0.0.0:" + str(port))
    for robot in enrolments(folder):
        who = "a robot" if robot.name == "robot" else f"robot '{robot.name[len('robot-'):]}'"
        lines += [f"to enrol {who}: copy {robot}/ to it, into .local/state/beastbt/fleet/ (never ca.key):",
                  f"    ssh ROBOT mkdir -p .local/state/beastbt/fleet && scp {robot}/* ROBOT:.local/state/beastbt/fleet/",
                  f"  and run there: beastbt serve --robot PROFILE --fleet tls/STATION:{port}"
                  + ("" if robot.name == "robot" else f" --name {robot.name[len('robot-'):]}"),
                  f"  (STATION: one of the names above)"]
    shared = folder / "robot.json5"
    if shared.is_file():
        config = "" if default else f" --fleet-config {shared}"
        lines.append(f"a simulated robot on this computer: beastbt serve --sim --name sim-1 --fleet "
                     f"{local_endpoint(listen)}{config}")
    return "\n".join(lines) + "\n"


def init_keys(args: argparse.Namespace) -> int:
    """``--init-keys DIR``: write the fleet's keys and configurations; 0, or 2 when they cannot be written."""
    import shutil
    import subprocess

    from beastbt.fleet.config import parse_endpoint
    from beastbt.fleet.credentials import init_keys as write_keys
    if shutil.which("openssl") is None:
        print("beastbt station: error: --init-keys needs the openssl command (apt install openssl)", file=sys.stderr)
        return EXIT_INVALID
    listen = args.listen or DEFAULT_LISTEN
    try:
        listen = parse_endpoint(listen, "--listen")
        problem = _robot_names_problem(args.robot_name)
        if problem:
            raise ValueError(problem)
        written = write_keys(Path(args.init_keys), args.host, listen, robots=args.robot_name)
    except (ValueError, FileExistsError, OSError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or str(exc)
        print(f"beastbt station: error: --init-keys {args.init_keys}: {str(detail).strip()[:300]}", file=sys.stderr)
        return EXIT_INVALID
    for path in written:
        print(path)
    print((Path(args.init_keys) / "README.txt").read_text(), end="")
    return EXIT_SUCCESS
