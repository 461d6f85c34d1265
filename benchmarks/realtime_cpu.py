"""CPU used by a run at ``--speed realtime``, as a share of one core, measured on this machine.

For the patrol, the line mission and the GPS route, recorded (the default) and with
``--no-record``: each runs as ``python -m beastbt run MISSION --speed realtime
--max-time T`` in a subprocess. The steady share is read while the mission
runs: the CPU time (user + system, from ``/proc/PID/stat``) of the run and of
its children (the recording writer) is sampled every 0.25 s, and the share is
the CPU spent between 3 s after the start-up (the recording writer starts then too) and 0.5 s before the mission's
end, over that wall time. The start-up (imports, loading, assembling) is
timed by a run of the same command with ``--max-time 0.05 s``. Beside it, the
older figure: the whole run's CPU (``getrusage(RUSAGE_CHILDREN)``) minus that
start-up run's, over the wall time minus its wall time; it also counts what
the end of a longer run costs more (closing a bigger recording), so it reads
higher.

The patrol is also run on robots/sim.yaml without its ``lidar:`` section:
the baseline, measured in the same run, against which the LiDAR's share
(emulator, driver, collision monitor, /scan) is the difference and the ratio.
Goal (issues 11 and 20): the patrol, with the LiDAR, under 5 % of one core.

``--missions`` picks the missions (default ``patrol,line,gps_route``):
``gps_route`` runs missions/gps_route.yaml with ``--seed 1`` as its comment says (the one seed mission
whose tree reads the fused pose: its GPS, IMU and EKF are awake, recorded or not);
``teleop`` runs missions/teleop.yaml with a joystick script: the demo's
(missions/joystick/teleop_demo.yaml) lasts 6.5 s, so a longer one of the same
kind is written for the run (enable held, the sticks changing every second,
released 0.5 s before the end). ``--console`` adds, for the patrol with the
LiDAR, recorded and not, and for the other missions recorded, runs with
``--console`` and one viewer, on the simulated camera and on the fake MJPEG camera (below): a client
process following ``WS /api/ws`` and ``WS /api/video`` as the page does (the
one of benchmarks/console.py); the viewer's own CPU is not counted (it is the
browser's), the console's server and encoder processes are (all the run's
descendants are). Each row also prints the run's peak resident memory (the
largest VmRSS sampled of the run and its descendants together). ``--json FILE``
writes the rows for docs/performance.md.

**Reps.** Every row runs ``--reps`` times (default 5), interleaved: each rep runs every row once in turn, so
that a machine that gets busier slows all rows alike; each figure is the median with the spread (lowest to
highest). The start-up is measured once per row (a run that ends at once).

**Without the simulator.** On the robot the Pi runs the drivers, the estimator, the tree, safety, the
recording and the console, not the physics, the device emulators (the ESP32 base, the GPS, the IMU, the
LiDAR's ray-casting) nor the camera's rendering and JPEG encoding (a camera does that in hardware). Every
process of a run charges the thread CPU time of that work to the simulator (``beastbt.sim.cpu_account``,
read here through ``BEASTBT_SIM_CPU_DIR`` at the same moments as ``/proc``), so each row also prints the
simulator's share over the same window and **beastbt without the simulator**, the row's share less it:
what the robot would spend, and what a Pi 4 table should scale for the robot (the whole share is for
someone running the simulator on a Pi). With ``--console`` the console rows also run on the robot's
camera path (``camera.format: mjpeg``: the simulator's fake USB camera renders and encodes in the run's
process, charged to the simulator, and its JPEG goes to the viewer untouched); on the simulated camera
the console's process renders the viewer's picture (the simulator's) and JPEG-encodes it (the console's,
though a robot with a JPEG camera would not).

Run: python benchmarks/realtime_cpu.py [--reps N] [--seconds T] [--missions patrol,line,gps_route,teleop] [--console]
      [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

import yaml

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from beastbt.sim.cpu_account import ENV_DIR, KINDS, SIMULATOR_KINDS, read_totals  # noqa: E402
MISSIONS = {"patrol": "missions/patrol.yaml", "line": "missions/line_to_intersection.yaml",
            "gps_route": "missions/gps_route.yaml", "teleop": "missions/teleop.yaml"}
EXTRA_ARGS = {"gps_route": ["--seed", "1"]}  # as the mission's own comment runs it
TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def _cpu_s(pid: int) -> Optional[float]:
    """User + system CPU seconds of process ``pid`` so far (None once it is gone)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def _rss_kib(pid: int) -> int:
    """Resident memory of process ``pid`` in KiB (0 once it is gone)."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except (FileNotFoundError, ProcessLookupError, ValueError):
        pass
    return 0


def _children(pid: int) -> list[int]:
    """The live descendants of ``pid`` (the recording writer; the console's server and encoder)."""
    parents: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat", encoding="ascii") as f:
                    parents[int(entry)] = int(f.read().rsplit(")", 1)[1].split()[1])
            except (FileNotFoundError, ProcessLookupError, IndexError, ValueError):
                pass
    out, frontier = [], {pid}
    while frontier:
        found = [child for child, parent in parents.items() if parent in frontier]
        out += found
        frontier = set(found)
    return out


def _free_port() -> int:
    """A TCP port free on 127.0.0.1 now (for the console)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_viewer(port: int, proc: subprocess.Popen) -> Optional[subprocess.Popen]:
    """Once the console on ``port`` answers, a viewer process following its state and video (None if it never
    answers while the run lives)."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    from console import VIEWER  # the same viewer as benchmarks/console.py
    deadline = time.monotonic() + 30
    while proc.poll() is None and time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
        except OSError:
            time.sleep(0.05)
            continue
        return subprocess.Popen([sys.executable, "-c", VIEWER, f"http://127.0.0.1:{port}"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return None


def joystick_script(path: Path, seconds: float) -> Path:
    """A joystick script like missions/joystick/teleop_demo.yaml but lasting ``seconds``: enable held, the sticks
    changing every second, released 0.5 s before the end."""
    pattern = [(0.8, 0.0), (0.5, 0.6), (0.5, -0.6), (0.3, 0.0), (0.0, 0.0)]
    events = [{"at": "1 s", "press": "enable"}]
    t = 1.5
    while t < seconds - 1.0:
        linear, angular = pattern[int(t) % len(pattern)]
        events.append({"at": f"{t} s", "linear": linear, "angular": angular})
        t += 1.0
    events += [{"at": f"{t} s", "linear": 0.0, "angular": 0.0}, {"at": f"{max(t, seconds - 0.5) + 0.1} s",
                                                                  "release": "enable"}]
    path.write_text(yaml.safe_dump(events, sort_keys=False), encoding="utf-8")
    return path


def sim_totals(folder: Path) -> list[float]:
    """Seconds per kind (:data:`KINDS` order) the run's processes charged to the simulator so far, summed over
    the totals files in ``folder`` (a process's file stays when it ends)."""
    out = [0.0] * len(KINDS)
    for path in folder.iterdir():
        totals = read_totals(path)
        if totals is not None:
            out = [a + b for a, b in zip(out, totals)]
    return out


Sample = tuple[float, float, list[float]]
"""(wall s since start, cpu s of the run and its descendants, simulator seconds per kind so far)."""


def run(mission: str, seconds: float, record: bool, runs_dir: str, robot: Optional[str] = None,
        extra: Optional[list[str]] = None,
        console: bool = False) -> tuple[float, float, dict, list[Sample]]:
    """(cpu s, wall s, summary, samples) of one realtime run of ``mission`` lasting at most ``seconds`` of mission
    time; ``extra`` arguments are added to the command, and ``console`` serves the console with one viewer. The
    summary gets ``peak_rss_mib`` (the run and its descendants' largest resident memory sampled)."""
    summary = Path(runs_dir) / "summary.json"
    args = [sys.executable, "-m", "beastbt", "run", mission, "--speed", "realtime", "--max-time", f"{seconds} s",
            "--summary", str(summary)] + (["--runs-dir", runs_dir] if record else ["--no-record"])
    args += ["--robot", robot, "--sim"] if robot else []
    args += extra or []
    port = _free_port() if console else 0
    args += ["--console", f"127.0.0.1:{port}"] if console else []
    sim_dir = Path(tempfile.mkdtemp(prefix="beastbt-simcpu-"))
    env = dict(os.environ, **{ENV_DIR: str(sim_dir)})
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    samples: list[Sample] = []
    children: dict[int, float] = {}  # the latest CPU seen of each child (kept once it has ended)
    viewer = _start_viewer(port, proc) if console else None
    peak_rss = 0
    while proc.poll() is None:
        rss = _rss_kib(proc.pid)
        for child in _children(proc.pid):
            children[child] = _cpu_s(child) or children.get(child, 0.0)
            rss += _rss_kib(child)
        peak_rss = max(peak_rss, rss)
        own = _cpu_s(proc.pid)
        if own is not None:
            samples.append((time.perf_counter() - t0, own + sum(children.values()), sim_totals(sim_dir)))
        time.sleep(0.25)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if viewer is not None:  # reaped after ``after``: its CPU (the browser's) is not in ``cpu``
        try:
            viewer.wait(timeout=10)
        except subprocess.TimeoutExpired:
            viewer.kill()
            viewer.wait()
    result = json.loads(summary.read_text())
    result["peak_rss_mib"] = peak_rss / 1024
    shutil.rmtree(sim_dir, ignore_errors=True)
    return cpu, wall, result, samples


def steady_share(samples: list[Sample], start_s: float, end_s: float) -> float:
    """CPU seconds per wall second between the samples nearest to ``start_s`` and ``end_s`` (wall s)."""
    inside = [s for s in samples if start_s <= s[0] <= end_s]
    if len(inside) < 2:
        return float("nan")
    (t0, c0, _), (t1, c1, _) = inside[0], inside[-1]
    return (c1 - c0) / max(t1 - t0, 1e-9)


def simulator_shares(samples: list[Sample], start_s: float, end_s: float) -> dict[str, float]:
    """The simulator's CPU seconds per wall second, per kind of :data:`SIMULATOR_KINDS`, over the same samples as
    :func:`steady_share` (NaN without two samples)."""
    inside = [s for s in samples if start_s <= s[0] <= end_s]
    if len(inside) < 2:
        return {kind: float("nan") for kind in SIMULATOR_KINDS}
    (t0, _, k0), (t1, _, k1) = inside[0], inside[-1]
    return {kind: (k1[i] - k0[i]) / max(t1 - t0, 1e-9) for i, kind in enumerate(KINDS) if kind in SIMULATOR_KINDS}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="mission seconds per run (default 30)")
    parser.add_argument("--missions", default="patrol,line,gps_route",
                        help="comma-separated, of " + ", ".join(MISSIONS) + " (default patrol,line,gps_route)")
    parser.add_argument("--console", action="store_true", help="also runs with --console and one viewer")
    parser.add_argument("--reps", type=int, default=5, help="runs of every row, interleaved (default 5)")
    parser.add_argument("--json", metavar="FILE", help="also write the rows as JSON to FILE")
    args = parser.parse_args()
    names = [n.strip() for n in args.missions.split(",") if n.strip()]
    unknown = [n for n in names if n not in MISSIONS]
    if unknown:
        parser.error(f"--missions: unknown {', '.join(unknown)}; expected some of {', '.join(MISSIONS)}")
    runs_dir = tempfile.mkdtemp(prefix="beastbt-realtime-")
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    profiles = {"sim": None}  # robot profile -> the --robot file (None: robots/sim.yaml as it is)
    for key, variant in (("no_lidar", {k: v for k, v in data.items() if k != "lidar"}),
                         ("mjpeg", dict(data, camera=dict(data["camera"], format="mjpeg")))):
        path = Path(runs_dir) / f"sim_{key}.yaml"
        path.write_text(yaml.safe_dump(variant, sort_keys=False), encoding="utf-8")
        profiles[key] = str(path)
    rows: list[tuple[str, str, bool, bool]] = []  # (mission, profile key, recorded, console)
    for name in names:
        if name == "patrol":
            rows += [("patrol", "sim", True, False), ("patrol", "no_lidar", True, False),
                     ("patrol", "sim", False, False), ("patrol", "no_lidar", False, False)]
            rows += [("patrol", camera, record, True) for camera in ("sim", "mjpeg")
                     for record in (True, False)] if args.console else []
        else:
            rows += [(name, "sim", True, False), (name, "sim", False, False)]
            rows += [(name, "sim", True, True), (name, "mjpeg", True, True)] if args.console else []
    joystick = joystick_script(Path(runs_dir) / "joystick.yaml", args.seconds)
    print(f"load before: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} (1, 5, 15 min)")
    print(f"each row: the whole run's share of one core, the simulator's part of it (physics, emulators, the "
          f"camera's rendering and encoding), and beastbt without the simulator (what the robot would spend); "
          f"{args.reps} reps, every rep runs every row once in turn; median (lowest-highest)")
    measured: dict[tuple, list[dict]] = {row: [] for row in rows}
    startup: dict[tuple, float] = {}
    startup_wall: dict[tuple, float] = {}
    for rep in range(args.reps):
        for row in rows:
            name, profile, record, console = row
            robot = profiles[profile]
            extra = EXTRA_ARGS.get(name, []) + (["--joystick", str(joystick)] if name == "teleop" else [])
            if rep == 0:  # the start-up (CPU and wall time of a run that ends at once), once per row
                startup[row], startup_wall[row] = run(MISSIONS[name], 0.05, record, runs_dir, robot, extra,
                                                      console)[:2]
            cpu, wall, summary, samples = run(MISSIONS[name], args.seconds, record, runs_dir, robot, extra, console)
            # The mission runs from about the start-up's wall time to that plus its seconds (realtime): its middle
            # part, 3 s in (the recording writer starts then too) to 0.5 s before its end.
            window = (startup_wall[row] + 3.0, startup_wall[row] + summary["sim_time_s"] - 0.5)
            share = steady_share(samples, *window)
            kinds = simulator_shares(samples, *window)
            measured[row].append({"share": share, "simulator": sum(kinds.values()), "kinds": kinds,
                                  "rss": summary["peak_rss_mib"], "sim_time_s": summary["sim_time_s"]})

    def med(row: tuple, key: str) -> float:
        return statistics.median(m[key] for m in measured[row])

    def spread(row: tuple, key: str, scale: float = 100.0, fmt: str = "{:5.2f}") -> str:
        values = [scale * m[key] for m in measured[row]]
        return (f"{fmt.format(statistics.median(values))} ({fmt.format(min(values)).strip()}-"
                f"{fmt.format(max(values)).strip()})")

    for m in measured.values():
        for x in m:
            x["without"] = x["share"] - x["simulator"]
    out_rows = []
    for row in rows:
        name, profile, record, console = row
        label = (("recorded" if record else "--no-record") + (", no LiDAR" if profile == "no_lidar" else "")
                 + (", console+viewer" if console else "") + (", mjpeg camera" if profile == "mjpeg" else ""))
        goal = "  (goal < 5 %)" if name == "patrol" and profile == "sim" and not console else ""
        kinds = {kind: statistics.median(x["kinds"][kind] for x in measured[row]) for kind in measured[row][0]["kinds"]}
        parts = ", ".join(f"{kind} {100 * v:.2f}" for kind, v in kinds.items() if v >= 0.00005)
        print(f"{name:7s} {label:38s} steady {spread(row, 'share')} % of one core{goal}, simulator "
              f"{spread(row, 'simulator')} %, without the simulator {spread(row, 'without')} %; start-up "
              f"{startup[row]:4.2f} s of CPU; peak RSS {spread(row, 'rss', 1.0, '{:5.1f}')} MiB"
              f"\n        simulator by kind, % of one core (medians): {parts or '-'}", flush=True)
        out_rows.append({"mission": name, "recorded": record, "lidar": profile != "no_lidar", "console": console,
                         "camera": "mjpeg" if profile == "mjpeg" else "sim", "reps": args.reps,
                         "sim_time_s": med(row, "sim_time_s"), "steady_share": med(row, "share"),
                         "steady_share_min": min(x["share"] for x in measured[row]),
                         "steady_share_max": max(x["share"] for x in measured[row]),
                         "simulator_share": med(row, "simulator"), "without_simulator_share": med(row, "without"),
                         "without_simulator_share_min": min(x["without"] for x in measured[row]),
                         "without_simulator_share_max": max(x["without"] for x in measured[row]),
                         "simulator_by_kind": kinds, "startup_cpu_s": startup[row], "peak_rss_mib": med(row, "rss")})
    steady = {(r["mission"], r["lidar"], r["recorded"]): (r["steady_share"], r["without_simulator_share"])
              for r in out_rows if not r["console"]}
    if "patrol" in names:
        for record in (True, False):
            (with_lidar, with_lidar_own), (without, without_own) = (steady[("patrol", True, record)],
                                                                    steady[("patrol", False, record)])
            print(f"patrol {'recorded' if record else '--no-record'}: the LiDAR adds "
                  f"{100 * (with_lidar - without):4.2f} % of one core (x{with_lidar / without:4.2f} the profile "
                  f"without it, medians of this run); without the simulator "
                  f"{100 * (with_lidar_own - without_own):4.2f} %")
    load = os.getloadavg()
    print(f"load after: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (1, 5, 15 min)")
    if args.json:
        Path(args.json).write_text(json.dumps({"seconds": args.seconds, "rows": out_rows, "load_after": load},
                                              indent=1), encoding="utf-8")
    # The rows, saved for benchmarks/check_docs.py (benchmarks/figures.py prints them): docs/performance.md quotes
    # them, and a Pi 4 estimate at x5 and x8 (its section "The factor").
    from figures import Figures
    figures = Figures("realtime_cpu")
    for r in out_rows:
        key = (f"{r['mission']}.{'recorded' if r['recorded'] else 'unrecorded'}_{'lidar' if r['lidar'] else 'no_lidar'}"
               f"{'_console' if r['console'] else ''}{'_mjpeg' if r['camera'] == 'mjpeg' else ''}")
        figures.put(f"{key}.pct", 100 * r["steady_share"])
        figures.put(f"{key}.pct_min", 100 * r["steady_share_min"])
        figures.put(f"{key}.pct_max", 100 * r["steady_share_max"])
        figures.put(f"{key}.without_simulator_pct_min", 100 * r["without_simulator_share_min"])
        figures.put(f"{key}.without_simulator_pct_max", 100 * r["without_simulator_share_max"])
        figures.put(f"{key}.pi4_x5_pct", 500 * r["steady_share"], 3)
        figures.put(f"{key}.pi4_x8_pct", 800 * r["steady_share"], 3)
        figures.put(f"{key}.simulator_pct", 100 * r["simulator_share"])
        figures.put(f"{key}.without_simulator_pct", 100 * r["without_simulator_share"])
        figures.put(f"{key}.without_simulator_pi4_x5_pct", 500 * r["without_simulator_share"], 3)
        figures.put(f"{key}.without_simulator_pi4_x8_pct", 800 * r["without_simulator_share"], 3)
        figures.put(f"{key}.rss_mib", r["peak_rss_mib"])
        figures.put(f"{key}.startup_cpu_s", r["startup_cpu_s"])
    if "patrol" in names:
        for record in (True, False):
            (with_lidar, with_own), (without, without_own) = (steady[("patrol", True, record)],
                                                              steady[("patrol", False, record)])
            mode = "recorded" if record else "unrecorded"
            figures.put(f"patrol.{mode}.lidar_added_points", 100 * (with_lidar - without))
            figures.put(f"patrol.{mode}.lidar_ratio", with_lidar / without)
            figures.put(f"patrol.{mode}.lidar_added_without_simulator_points", 100 * (with_own - without_own))
    figures.save()


if __name__ == "__main__":
    main()
