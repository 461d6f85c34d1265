"""The fleet on loopback: the station's CPU with N robots, a command's round trip, estop-all, bandwidth.

    python benchmarks/fleet.py [--robots 20] [--commands 200]

Starts ``beastbt station`` and N ``beastbt serve --sim`` robots (separate processes, random
free ports) and prints:

* the station's CPU (% of one core, from /proc) with no robot (the baseline) and with N idle,
  then N running, robots;
* a command's round trip, station API to the robot's acknowledgement (``estop`` and
  ``estop_reset`` in turn, each answered by the robot's queryable), p50 and p99 in ms;
* ``POST /api/estop-all`` to every robot's commanded speed at zero, as its state stream shows it
  (an upper bound: a state goes out every 0.175 s);
* each robot's bandwidth on ``beastbt/<name>/**`` (kB/s) while idle and while running.

The issue's targets: station < 20 % of a core with 20 robots; p99 < 50 ms; wheels at zero
within 0.5 s; a state stream under 50 kB/s.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from typing import Any

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "tests"))
from fleet_support import free_port, http  # noqa: E402  (the tests' loopback helpers)

LONG = "mission: long_drive\nsteps:\n  - drive: {distance: 50 m, speed: 0.3 m/s}\n"


def cpu_s(pid: int) -> float:
    """CPU time (user + system, s) the process has used."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cpu_percent(pid: int, seconds: float) -> float:
    """% of one core the process uses over ``seconds``."""
    c0, t0 = cpu_s(pid), time.monotonic()
    time.sleep(seconds)
    return 100.0 * (cpu_s(pid) - c0) / (time.monotonic() - t0)


def robots(base: str) -> dict[str, dict]:
    """The station's robots by name."""
    return {r["name"]: r for r in http("GET", f"{base}/api/robots")[1]["robots"]}


def wait_for(check: Any, timeout_s: float, what: str) -> None:
    """Poll ``check`` until true, or exit naming ``what``."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if check():
            return
        time.sleep(0.05)
    sys.exit(f"not within {timeout_s} s: {what}")


def bandwidth(endpoint: str, name: str, seconds: float) -> float:
    """kB/s on ``beastbt/<name>/**`` as a plain Zenoh client receives it."""
    import zenoh
    config = zenoh.Config()
    for key, value in {"mode": "client", "connect/endpoints": [endpoint], "scouting/multicast/enabled": False}.items():
        config.insert_json5(key, json.dumps(value))
    total = [0]
    session = zenoh.open(config)
    try:
        sub = session.declare_subscriber(f"beastbt/{name}/**", lambda s: total.__setitem__(
            0, total[0] + len(s.payload.to_bytes()) + len(str(s.key_expr))))
        time.sleep(seconds)
        sub.undeclare()
    finally:
        session.close()
    return total[0] / seconds / 1000.0


def main() -> None:
    """Run the measurements and print them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=20)
    parser.add_argument("--commands", type=int, default=200)
    args = parser.parse_args()
    work = tempfile.mkdtemp(prefix="beastbt-fleet-bench-")
    zport, hport = free_port(), free_port()
    endpoint, base = f"tcp/127.0.0.1:{zport}", f"http://127.0.0.1:{hport}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "stdin": subprocess.DEVNULL, "cwd": work}
    # plain TCP on loopback (--insecure-loopback): the bandwidth is measured by a plain Zenoh client of the router
    procs = [subprocess.Popen([sys.executable, "-m", "beastbt", "station", "--insecure-loopback", "--listen", endpoint,
                               "--console", f"127.0.0.1:{hport}"], **quiet)]
    station = procs[0]
    try:
        wait_for(lambda: _up(base), 20, "the station answers")
        baseline = cpu_percent(station.pid, 3.0)
        names = [f"r{i}" for i in range(args.robots)]
        for name in names:
            procs.append(subprocess.Popen([sys.executable, "-m", "beastbt", "serve", "--sim", "--insecure-loopback",
                                           "--name", name, "--fleet", endpoint, "--no-record"], **quiet))
        wait_for(lambda: set(names) <= {n for n, r in robots(base).items() if r["alive"]}, 60 + 2 * args.robots,
                 "every robot listed")
        idle = cpu_percent(station.pid, 5.0)
        idle_bw = bandwidth(endpoint, names[0], 3.0)
        times = []
        for i in range(args.commands):
            control = "estop" if i % 2 == 0 else "estop_reset"
            t0 = time.perf_counter()
            status, _ = http("POST", f"{base}/api/robots/{names[0]}/{control}", b"{}")
            times.append(1000.0 * (time.perf_counter() - t0))
            assert status == 200, status
        times.sort()
        p50, p99 = statistics.median(times), times[min(len(times) - 1, int(0.99 * len(times)))]
        for name in names:
            http("POST", f"{base}/api/robots/{name}/mission", LONG.encode(), "application/yaml")
        wait_for(lambda: all(r["status"] == "running" and r["pose"] and abs(r["pose"]["x"]) > 0.05
                             for r in robots(base).values()), 60, "every robot drives")
        running = cpu_percent(station.pid, 5.0)
        running_bw = bandwidth(endpoint, names[0], 3.0)
        t0 = time.monotonic()
        http("POST", f"{base}/api/estop-all", b"")
        wait_for(lambda: all(r["estop"] and r["status"] != "running" for r in robots(base).values()), 5,
                 "every robot stopped")
        stop_s = time.monotonic() - t0
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in procs:
            try:
                proc.wait(15)
            except subprocess.TimeoutExpired:
                proc.kill()
    n = args.robots
    print(f"station CPU, % of a core: no robot {baseline:.1f} (baseline); {n} idle robots {idle:.1f} "
          f"({idle / max(baseline, 0.1):.1f}x); {n} running {running:.1f} ({running / max(baseline, 0.1):.1f}x); "
          f"target < 20")
    print(f"command round trip (station API -> robot's ack, {args.commands} commands): p50 {p50:.1f} ms, "
          f"p99 {p99:.1f} ms; target p99 < 50")
    print(f"estop-all -> every robot's run ended by its e-stop, as the station sees it: {1000 * stop_s:.0f} ms "
          f"(an upper bound: states go out every 0.175 s); target wheels at zero < 500 ms")
    print(f"bandwidth of one robot (state + events, no video): idle {idle_bw:.1f} kB/s, running {running_bw:.1f} "
          f"kB/s; target < 50")
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("fleet")
    for key, value in (("station_baseline_pct", baseline), ("station_idle_pct", idle),
                       ("station_running_pct", running), ("command_p50_ms", p50), ("command_p99_ms", p99),
                       ("estop_all_ms", 1000 * stop_s), ("idle_kbps", idle_bw), ("running_kbps", running_bw)):
        figures.put(key, value)
    figures.put("robots", n)
    figures.save()


def _up(base: str) -> bool:
    try:
        http("GET", f"{base}/api/robots")
        return True
    except (urllib.error.URLError, ConnectionError):
        return False


if __name__ == "__main__":
    main()
