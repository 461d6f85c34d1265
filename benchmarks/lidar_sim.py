"""What the simulated LiDAR costs: the emulator per scan, and the patrol's sim speed with and without it.

Prints:
1. the LD19 and RPLIDAR A1 emulators' cost per revolution (ray casting,
   noise, packing the model's bytes, feeding the port; the driver's decoding
   is benchmarks/lidar_decode.py's business), stepped as the simulator steps
   them (100 Hz) and read as the run loop reads them (20 Hz), in worlds/corridor_person.yaml (4 walls, a walking person)
   and worlds/campus_obstacles.yaml, against two baselines measured in the
   same run: a bare NumPy ray-vs-segment intersection of the same size (the
   rays of one revolution against the world's segments: the least a caster
   does) and the simulator's physics step (times the steps of one
   revolution). Goal of issue 20: at most 0.3 ms per scan.
2. the patrol's real-time factor (sim seconds per wall second) on
   robots/sim.yaml without its LiDAR (the baseline), with it asleep (the
   collision monitor turned off and nothing else reading the scan), and with
   it as users get it (the collision monitor reads every scan: polled,
   decoded, emulated and checked every tick); and recorded, without the
   LiDAR and with it (each revolution on /scan as well). Goal of issue 20:
   at least 100x.

Each figure is the median of several measurements (this machine is shared).
``--cpu`` times with CPU time instead of the wall clock: the emulator with
this thread's, a patrol with this process's and its recording writer's (the
real-time factor is then sim seconds per CPU second), so that other
processes on a shared machine do not count.

Run: python benchmarks/lidar_sim.py [--seconds 20] [--seeds 2] [--repeats 5] [--cpu]
"""

from __future__ import annotations

import argparse
import re
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.assembly import prepare  # noqa: E402
from beastbt.robot.profile import load_profile  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402
from beastbt.sim.lidar_emulator import RayCaster, make_emulator  # noqa: E402
from beastbt.sim.robot import build_simulator  # noqa: E402
from beastbt.sim.world import load_world  # noqa: E402

PATROL = str(REPO / "missions" / "patrol.yaml")
TIMER = time.perf_counter
"""The emulator's timer (``--cpu``: time.thread_time)."""
CPU = False
"""``--cpu``: a patrol's time is its CPU time (this process and its children), not the wall clock's."""


def _patrol_clock() -> float:
    if not CPU:
        return time.perf_counter()
    children = resource.getrusage(resource.RUSAGE_CHILDREN)  # the recording writer, once it has ended
    return time.process_time() + children.ru_utime + children.ru_stime
WORLDS = ("corridor_person.yaml", "campus_obstacles.yaml")


def emulator_cost(kind: str, world_name: str, seconds: float) -> tuple[float, int, float, float]:
    """(ms per revolution, revolutions, bare-intersection ms, physics ms per revolution) for ``kind``."""
    world = load_world(REPO / "worlds" / world_name)
    sim = build_simulator(load_profile("sim"), world, seed=1)
    device = make_emulator(kind, RayCaster(world.walls, world.obstacles), sim.truth, sim.drive.contact,
                           (0.0, 0.0, 0.0), np.random.default_rng(1))
    if kind == "rplidar_a1":  # as its driver does: motor on (DTR low), SCAN; measured from when it is at speed
        device.port.dtr = False
        device.port.write(bytes((0xA5, 0x20)))
    sim.drive.set_body_targets(0.2, 0.3)  # the robot drives a circle: the world turns past the LiDAR
    dt = sim.physics_dt_s
    steps = int(round(seconds / dt))
    spent = 0.0
    physics = 0.0
    t = 0.0
    for step in range(steps):
        p0 = TIMER()
        sim.drive.step(dt)
        p1 = TIMER()
        t += dt
        device.update(t, dt)
        if step % 5 == 4:  # a driver takes them at each 20 Hz tick (the LD19's port is fed then)
            device.port.read(device.port.in_waiting)
        spent += TIMER() - p1
        physics += p1 - p0
    revolutions = device.casts * device.chunk_s * device.model.rate_hz  # revolutions cast
    # The baseline: one revolution's rays against the world's segments, t and u and the nearest, nothing else.
    n = int(round(device.model.points_per_s / device.model.rate_hz))
    segs = np.array([(w.x1, w.y1, w.x2, w.y2) for w in world.walls] +
                    [(*o.corners()[i], *o.corners()[(i + 1) % 4]) for o in world.obstacles if hasattr(o, "corners")
                     for i in range(4)], dtype=float).reshape(-1, 4)
    angles = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    reps = 300
    b0 = TIMER()
    for _ in range(reps):
        dx, dy = np.cos(angles), np.sin(angles)
        ex, ey = segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1]
        wx, wy = segs[:, 0] - 1.0, segs[:, 1]
        with np.errstate(divide="ignore"):
            inv = 1.0 / (np.outer(dx, ey) - np.outer(dy, ex))
        tt = (wx * ey - wy * ex) * inv
        uu = (np.outer(dy, wx) - np.outer(dx, wy)) * inv
        tt[(uu < 0) | (uu > 1) | (tt <= 0)] = np.inf
        tt.min(axis=1)
    bare = (TIMER() - b0) / reps
    physics_per_revolution = physics / steps / (device.model.rate_hz * dt)
    return spent / revolutions * 1e3, int(round(revolutions)), bare * 1e3, physics_per_revolution * 1e3


def rtf(robot: str, seeds: int, lidar_awake: bool, runs_dir: str = "") -> list[float]:
    """Sim seconds per wall second of whole patrol runs on ``robot`` (loading excluded); ``lidar_awake`` says
    whether the LiDAR is expected to be read (checked)."""
    out = []
    for seed in range(1, seeds + 1):
        p = prepare(PATROL, RunOptions(robot=robot, seed=seed, record=bool(runs_dir), runs_dir=runs_dir or "runs",
                                       simulate=True))
        assert ("lidar" in p.run.io.sensors) == lidar_awake, f"the LiDAR is not as asked on {robot}"
        t0 = _patrol_clock()
        with open("/dev/null", "w") as devnull:
            s = execute(p, devnull)
        out.append(s["sim_time_s"] / (_patrol_clock() - t0))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per emulator measurement")
    ap.add_argument("--seeds", type=int, default=2, help="patrol runs per configuration")
    ap.add_argument("--repeats", type=int, default=5, help="emulator measurements per model and world (median)")
    ap.add_argument("--cpu", action="store_true", help="time with CPU time, not the wall clock")
    args = ap.parse_args()
    global TIMER, CPU
    TIMER, CPU = (time.thread_time, True) if args.cpu else (time.perf_counter, False)
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("lidar_sim")
    print("1. LiDAR emulator, per revolution (ray casting + noise + bytes), stepped at the physics rate")
    for world in WORLDS:
        for kind in ("ld19", "rplidar_a1"):
            runs = [emulator_cost(kind, world, args.seconds) for _ in range(args.repeats)]
            ms, revs, bare, physics = (statistics.median(r[i] for r in runs) for i in range(4))
            print(f"   {kind:10s} {world:22s} {ms:6.3f} ms/scan over {revs:.0f} scans | bare NumPy intersection "
                  f"{bare:6.3f} ms (x{ms / bare:4.1f}) | physics steps of one revolution {physics:6.3f} ms "
                  f"(x{ms / physics:4.2f})   goal <= 0.3 ms: {'OK' if ms <= 0.3 else 'MISSED'}")
            figures.put(f"emulator.{kind}.{Path(world).stem}_ms", ms)
    print(f"2. Patrol real-time factor (sim s per {'CPU' if CPU else 'wall'} s)")
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    with tempfile.TemporaryDirectory() as tmp:
        bare_robot = Path(tmp) / "sim_no_lidar.yaml"
        bare_robot.write_text(yaml.safe_dump({k: v for k, v in data.items() if k != "lidar"}, sort_keys=False),
                              encoding="utf-8")
        unmonitored = Path(tmp) / "sim_no_monitor.yaml"
        unmonitored.write_text(yaml.safe_dump({**data, "collision_monitor": {"enabled": False}}, sort_keys=False),
                               encoding="utf-8")
        runs = str(Path(tmp) / "runs")
        rows = [("no LiDAR in the profile", str(bare_robot), False, ""),
                ("LiDAR asleep (no monitor)", str(unmonitored), False, ""),
                ("LiDAR + collision monitor", "sim", True, ""),
                ("recorded, no LiDAR in the profile", str(bare_robot), False, runs),
                ("recorded, LiDAR + monitor, /scan", "sim", True, runs)]
        results = {}
        for label, robot, awake, record in rows:
            results[label] = statistics.median(rtf(robot, args.seeds, awake, record))
    base = results[rows[0][0]]
    for label, value in results.items():
        print(f"   {label:34s} {value:7.0f}x real time  ({value / base:4.2f} of the profile without LiDAR)"
              f"   goal >= 100x: {'OK' if value >= 100 else 'MISSED'}")
        key = re.sub(r"[^a-z0-9]+", "_", label.lower()).strip("_")
        figures.put(f"rtf.{key}", value)
        figures.put(f"rtf.{key}_of_no_lidar", value / base)
    figures.save()


if __name__ == "__main__":
    main()
