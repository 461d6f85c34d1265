"""``beastbt station``: the fleet's station, a Zenoh router and an HTTP API for every robot on it (docs/fleet.md).

Exit status: 0 when stopped (Ctrl-C, SIGTERM), 2 when it cannot start (an
address it cannot listen on, a bad ``--fleet-config``).
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

EXIT_SUCCESS, EXIT_FAILURE, EXIT_INVALID = 0, 1, 2
DEFAULT_LISTEN = "tcp/127.0.0.1:7447"
DEFAULT_CONSOLE = "127.0.0.1:8090"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``beastbt station``."""
    p.add_argument("--listen", default=DEFAULT_LISTEN, metavar="ENDPOINT",
                   help=f"where robots connect (Zenoh endpoint, default {DEFAULT_LISTEN}: this computer only; "
                        f"tcp/0.0.0.0:7447 for every network, with --fleet-config for TLS)")
    p.add_argument("--console", default=DEFAULT_CONSOLE, metavar="[HOST:]PORT",
                   help=f"where the station's page and HTTP API listen (default {DEFAULT_CONSOLE}); off loopback "
                        f"they need the token printed at start")
    p.add_argument("--console-token", choices=("auto", "always"), default="auto",
                   help="auto (default): the token is needed off loopback only; always: on loopback too")
    p.add_argument("--fleet-config", metavar="FILE", help="a standard Zenoh JSON5 configuration for the router "
                                                          "(TLS, credentials, access control)")
    p.add_argument("--simulate", type=int, default=0, metavar="N",
                   help="also start N simulated robots (sim-1 ... sim-N, each a 'beastbt serve --sim') side by side")
    p.add_argument("--world", help="with --simulate: the world they share (default: an empty plain)")
    p.add_argument("--speed", default="realtime", help="with --simulate: realtime (default), max or a factor")
    p.add_argument("--runs-dir", default="runs", help="with --simulate: where their run folders go (default ./runs)")
    p.add_argument("--init-keys", metavar="DIR", help="write a fleet's CA, the station's and the robots' "
                                                      "certificates, DIR/station.json5 and DIR/robot.json5 (mutual "
                                                      "TLS, only the station commands) and a how-to; then exit")
    p.add_argument("--robot-name", action="append", default=[], metavar="NAME",
                   help="with --init-keys: give robot NAME a certificate of its own, with which it may use only its "
                        "own keys (repeatable); without it, one certificate for every robot")
    p.add_argument("--host", action="append", default=[], metavar="NAME",
                   help="with --init-keys: a name or address robots reach the station by (repeatable; localhost "
                        "and 127.0.0.1 always)")


def command(args: argparse.Namespace) -> int:
    """Run the station until Ctrl-C or SIGTERM (or, with ``--init-keys``, write the keys and exit)."""
    if args.init_keys:
        return init_keys(args)
    from beastbt.core.errors import InvalidInput
    from beastbt.fleet.config import parse_endpoint
    from beastbt.live.endpoint import parse_endpoint as parse_http
    try:
        listen = parse_endpoint(args.listen, "--listen")
        host, port = parse_http(args.console, "--console")
    except ValueError as exc:
        print(f"beastbt station: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    if args.simulate < 0 or (args.simulate and (args.fleet_config or not listen.startswith("tcp/"))):
        print("beastbt station: error: --simulate N takes N >= 0, on a plain tcp/ --listen (simulated robots "
              "have no keys)", file=sys.stderr)
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
    station = Station(listen, args.fleet_config)
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
    if not args.fleet_config and not is_loopback(listen.split("/", 1)[1].rsplit(":", 1)[0].strip("[]")):
        print("beastbt station: warning: the fleet link is plain TCP off loopback: anyone on that network can read "
              "and command the robots; use --fleet-config with the keys of 'beastbt station --init-keys DIR'",
              file=sys.stderr, flush=True)
    print(f"station page and API: {server.url}", flush=True)
    simulated = []
    if args.simulate > 0:
        import tempfile
        from pathlib import Path

        from beastbt.fleet.simulate import start_robots
        worlds = Path(tempfile.mkdtemp(prefix="beastbt-simulate-"))
        simulated = start_robots(args.simulate, args.world, listen.replace("0.0.0.0", "127.0.0.1"), args.speed,
                                 worlds, args.runs_dir)
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


def init_keys(args: argparse.Namespace) -> int:
    """``--init-keys DIR``: write the fleet's keys and configurations; 0, or 2 when they cannot be written."""
    import shutil
    import subprocess
    from pathlib import Path

    from beastbt.fleet.config import parse_endpoint
    from beastbt.fleet.credentials import init_keys as write_keys
    if shutil.which("openssl") is None:
        print("beastbt station: error: --init-keys needs the openssl command (apt install openssl)", file=sys.stderr)
        return EXIT_INVALID
    listen = args.listen if args.listen != DEFAULT_LISTEN else DEFAULT_LISTEN.replace("tcp/", "tls/")
    try:
        listen = parse_endpoint(listen, "--listen")
        from beastbt.fleet.keys import name_problem
        for name in args.robot_name:
            problem = name_problem(name) or ("'station' is the station's own name" if name == "station" else None)
            if problem:
                raise ValueError(f"--robot-name {name[:80]}: {problem}")
        written = write_keys(Path(args.init_keys), args.host, listen, robots=args.robot_name)
    except (ValueError, FileExistsError, OSError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or str(exc)
        print(f"beastbt station: error: --init-keys {args.init_keys}: {str(detail).strip()[:300]}", file=sys.stderr)
        return EXIT_INVALID
    for path in written:
        print(path)
    print((Path(args.init_keys) / "README.txt").read_text(), end="")
    return EXIT_SUCCESS
