"""What the simulated LiDAR costs: the emulator per scan, and the patrol's sim speed with and without it.

Prints:
1. the LD19 and RPLIDAR A1 emulators' cost per revolution (ray casting,
   noise, packing the model's bytes, feeding the port; the driver's decoding
   is benchmarks/lidar_decode.py's business), stepped as the simulator steps
   them (100 Hz) in worlds/corridor_person.yaml (4 walls, a walking person)
   and worlds/campus_obstacles.yaml, against two baselines measured in the
   same run: a bare NumPy ray-vs-segment intersection of the same size (the
   rays of one revolution against the world's segments: the least a caster
   does) and the simulator's physics step (times the steps of one
   revolution). Goal of issue 20: at most 0.3 ms per scan.
2. the patrol's real-time factor (sim seconds per wall second) on
   robots/sim.yaml without its LiDAR, with it asleep (nothing reads the scan:
   the default for an unrecorded patrol), and with it awake (kept awake as a
   reader of ``scan`` such as the collision monitor would keep it: polled,
   decoded and emulated every tick); and recorded, without the LiDAR and with
   it (each revolution on /scan). Goal of issue 20: at least 100x.

Each figure is the median of several measurements (this machine is shared).

Run: python benchmarks/lidar_sim.py [--seconds 20] [--seeds 2] [--repeats 5]
"""

from __future__ import annotations

import argparse
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
from beastbt.parts.lidar import LidarPart  # noqa: E402
from beastbt.robot.part import Part  # noqa: E402
from beastbt.robot.profile import load_profile  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402
from beastbt.sim.lidar_emulator import RayCaster, make_emulator  # noqa: E402
from beastbt.sim.robot import build_simulator  # noqa: E402
from beastbt.sim.world import load_world  # noqa: E402

PATROL = str(REPO / "missions" / "patrol.yaml")
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
    for _ in range(steps):
        p0 = time.perf_counter()
        sim.drive.step(dt)
        p1 = time.perf_counter()
        t += dt
        device.update(t, dt)
        spent += time.perf_counter() - p1
        physics += p1 - p0
        device.port.read(device.port.in_waiting)  # a driver would take them
    revolutions = device.casts * device.chunk_s * device.model.rate_hz  # revolutions cast
    # The baseline: one revolution's rays against the world's segments, t and u and the nearest, nothing else.
    n = int(round(device.model.points_per_s / device.model.rate_hz))
    segs = np.array([(w.x1, w.y1, w.x2, w.y2) for w in world.walls] +
                    [(*o.corners()[i], *o.corners()[(i + 1) % 4]) for o in world.obstacles if hasattr(o, "corners")
                     for i in range(4)], dtype=float).reshape(-1, 4)
    angles = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    reps = 300
    b0 = time.perf_counter()
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
    bare = (time.perf_counter() - b0) / reps
    physics_per_revolution = physics / steps / (device.model.rate_hz * dt)
    return spent / revolutions * 1e3, int(round(revolutions)), bare * 1e3, physics_per_revolution * 1e3


def rtf(robot: str, seeds: int, lidar_awake: bool, runs_dir: str = "") -> list[float]:
    """Sim seconds per wall second of whole patrol runs on ``robot`` (loading excluded)."""
    out = []
    saved = LidarPart.sleep
    try:
        if lidar_awake:
            LidarPart.sleep = Part.sleep  # type: ignore[method-assign]  # as if something read the scan
        for seed in range(1, seeds + 1):
            p = prepare(PATROL, RunOptions(robot=robot, seed=seed, record=bool(runs_dir), runs_dir=runs_dir or "runs",
                                           simulate=True))
            awake = "lidar" in p.run.io.sensors
            assert awake == (lidar_awake or bool(runs_dir)) or robot != "sim", "the LiDAR is not as asked"
            t0 = time.perf_counter()
            with open("/dev/null", "w") as devnull:
                s = execute(p, devnull)
            out.append(s["sim_time_s"] / (time.perf_counter() - t0))
    finally:
        LidarPart.sleep = saved  # type: ignore[method-assign]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per emulator measurement")
    ap.add_argument("--seeds", type=int, default=2, help="patrol runs per configuration")
    ap.add_argument("--repeats", type=int, default=5, help="emulator measurements per model and world (median)")
    args = ap.parse_args()
    print("1. LiDAR emulator, per revolution (ray casting + noise + bytes), stepped at the physics rate")
    for world in WORLDS:
        for kind in ("ld19", "rplidar_a1"):
            runs = [emulator_cost(kind, world, args.seconds) for _ in range(args.repeats)]
            ms, revs, bare, physics = (statistics.median(r[i] for r in runs) for i in range(4))
            print(f"   {kind:10s} {world:22s} {ms:6.3f} ms/scan over {revs:.0f} scans | bare NumPy intersection "
                  f"{bare:6.3f} ms (x{ms / bare:4.1f}) | physics steps of one revolution {physics:6.3f} ms "
                  f"(x{ms / physics:4.2f})   goal <= 0.3 ms: {'OK' if ms <= 0.3 else 'MISSED'}")
    print("2. Patrol real-time factor (sim s per wall s)")
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    data.pop("lidar", None)
    with tempfile.TemporaryDirectory() as tmp:
        bare_robot = Path(tmp) / "sim_no_lidar.yaml"
        bare_robot.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        runs = str(Path(tmp) / "runs")
        rows = [("no LiDAR in the profile", str(bare_robot), False, ""), ("LiDAR asleep (default)", "sim", False, ""),
                ("LiDAR awake (read every tick)", "sim", True, ""),
                ("recorded, no LiDAR in the profile", str(bare_robot), False, runs),
                ("recorded, LiDAR on /scan", "sim", False, runs)]
        results = {}
        for label, robot, awake, record in rows:
            results[label] = statistics.median(rtf(robot, args.seeds, awake, record))
    base = results[rows[0][0]]
    for label, value in results.items():
        print(f"   {label:34s} {value:7.0f}x real time  ({value / base:4.2f} of the profile without LiDAR)"
              f"   goal >= 100x: {'OK' if value >= 100 else 'MISSED'}")


if __name__ == "__main__":
    main()
