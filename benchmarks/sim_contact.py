"""What contact costs the simulator: one physics step with walls and obstacles against one without, in one run.

Prints, per physics step (the robot driving, slip noise on, as in a run):
1. the step in a world with nothing to touch (the baseline);
2. the corridor (4 walls), the campus with its 9 obstacles, the corridor with
   a pacing person, and a crowded yard (40 walls, 100 boxes, 100 posts,
   10 persons), each as a ratio to the baseline;
3. the exact clearance in plain floats against NumPy among 4 to 64 things
   (which sets ``SMALL_WORLD``), and the exact geometry on its own, for
   comparison: one ``clearance`` and one
   swept test (``free_fraction`` forced) in the crowded yard, which is what a
   step would cost if the lower bound never spared it;
4. the patrol's real-time factor on worlds/corridor.yaml, and on
   worlds/corridor_person.yaml (the person meets the robot, waits and steps
   around it), against the same run in the same corridor without its walls
   (whole runs through ``execute``, robots/sim.yaml with its LiDAR).

The bound (``beastbt.sim.contact``) skips the geometry while everything is
further than the robot can reach, so items 1-2 should stay close to 1x.

Run: python benchmarks/sim_contact.py [--steps N]
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.assembly import prepare  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402
from beastbt.sim.contact import ContactWorld  # noqa: E402
from beastbt.sim.dynamics import DiffDriveSim, DriveModel, Wall  # noqa: E402
from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle, Person  # noqa: E402
from beastbt.sim.truth import RobotTruth  # noqa: E402
from beastbt.sim.world import load_world  # noqa: E402

DT_S = 0.01  # robots/sim.yaml's 100 Hz physics


def model() -> DriveModel:
    """robots/sim.yaml's simulated base."""
    return DriveModel(track_width_m=0.17, max_wheel_speed_mps=0.5, max_wheel_accel_mps2=1.5,
                      motor_time_constant_s=0.08, slip_sigma=0.02, slip_bias=0.005, footprint_radius_m=0.15)


def crowded_yard() -> tuple[list[Wall], list]:
    """A 50 m x 50 m yard fenced by 40 wall pieces, with 100 boxes, 100 posts and 10 pacing persons."""
    rng = np.random.default_rng(7)
    walls = []
    for i in range(10):
        a, b = -25 + 5 * i, -20 + 5 * i
        walls += [Wall(a, -25, b, -25), Wall(a, 25, b, 25), Wall(-25, a, -25, b), Wall(25, a, 25, b)]
    obstacles: list = []
    for _ in range(100):
        x, y = rng.uniform(-24, 24, 2)
        if abs(y) > 1.5:  # keep the robot's lane (y = 0) free, as the benchmark drives along it
            obstacles.append(BoxObstacle(float(x), float(y), 0.5, 0.8, float(rng.uniform(0, math.pi))))
        x, y = rng.uniform(-24, 24, 2)
        if abs(y) > 1.5:
            obstacles.append(CylinderObstacle(float(x), float(y), 0.15))
    for i in range(10):
        obstacles.append(Person(0.25, 1.0, ((-20.0, 3.0 + i), (20.0, 3.0 + i)), loop=True))
    return walls, obstacles


def per_step_us(walls: list, obstacles: list, steps: int, start=(0.0, 0.0)) -> float:
    """Mean wall time of one physics step driving east then back at 0.3 m/s, microseconds."""
    contact = ContactWorld(walls, obstacles, 0.15) if walls or obstacles else None
    sim = DiffDriveSim(model(), RobotTruth(x=start[0], y=start[1]), np.random.default_rng(1), walls=list(walls),
                       contact=contact)
    t0 = time.perf_counter()
    for i in range(steps):
        if i % 1000 == 0:  # back and forth every 10 s, so the robot stays in the world
            sim.set_body_targets(0.3 if (i // 1000) % 2 == 0 else -0.3, 0.0)
        sim.step(DT_S)
    return (time.perf_counter() - t0) / steps * 1e6


def exact_us(walls: list, obstacles: list, calls: int) -> tuple[float, float]:
    """Mean wall time of one exact clearance and of one swept test, microseconds."""
    world = ContactWorld(walls, obstacles, 0.15)
    t0 = time.perf_counter()
    for i in range(calls):
        world.clearance(0.001 * i, 0.0)
    clear = (time.perf_counter() - t0) / calls * 1e6
    t0 = time.perf_counter()
    for i in range(calls):
        world._ref = None  # force the geometry: no bound to spare it
        world.free_fraction(0.001 * i, 0.0, 0.001 * i + 0.003, 0.0)
    sweep = (time.perf_counter() - t0) / calls * 1e6
    return clear, sweep


def timed(clearance, calls: int) -> float:
    """Mean wall time of one call of a clearance function, microseconds."""
    t0 = time.perf_counter()
    for i in range(calls):
        clearance(0.001 * i, 0.0)
    return (time.perf_counter() - t0) / calls * 1e6


def patrol_rtf(world: str) -> float:
    """Sim seconds per wall second of the patrol in ``world`` (loading excluded)."""
    p = prepare(str(REPO / "missions" / "patrol.yaml"), RunOptions(seed=1, record=False, world=world))
    t0 = time.perf_counter()
    with open("/dev/null", "w") as devnull:
        s = execute(p, devnull)
    return s["sim_time_s"] / (time.perf_counter() - t0)


def main() -> None:
    """Print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=30000, help="physics steps per figure (default 30000)")
    steps = ap.parse_args().steps
    corridor = load_world(REPO / "worlds" / "corridor.yaml")
    campus = load_world(REPO / "worlds" / "campus_obstacles.yaml")
    person = load_world(REPO / "worlds" / "corridor_person.yaml")
    yard = crowded_yard()
    per_step_us([], [], 2000)  # warm up
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("sim_contact")
    base = per_step_us([], [], steps)
    print(f"physics step, nothing to touch:        {base:7.2f} us")
    figures.put("step.nothing_us", base)
    for name, (walls, obstacles, start) in {
        "corridor (4 walls)": (corridor.walls, corridor.obstacles, (1.0, 0.0)),
        "campus_obstacles (9)": (campus.walls, campus.obstacles, (0.0, -3.0)),
        "corridor_person (4 walls, 1 person)": (person.walls, person.obstacles, (1.0, 0.0)),
        "crowded yard (40 walls, ~200 things, 10 persons)": (*yard, (0.0, 0.0)),
    }.items():
        cost = per_step_us(list(walls), list(obstacles), steps, start)
        print(f"physics step, {name + ':':38s} {cost:7.2f} us  = {cost / base:5.2f}x")
        key = re.sub(r"[^a-z0-9]+", "_", name.split(" (")[0].lower()).strip("_")
        figures.put(f"step.{key}_us", cost)
        figures.put(f"step.{key}_ratio", cost / base)
    for n in (4, 8, 16, 32, 64):  # where plain floats stop beating NumPy (SMALL_WORLD in beastbt/sim/contact.py)
        world = ContactWorld(yard[0][:n // 2], [o for o in yard[1] if not isinstance(o, Person)][:n - n // 2], 0.15)
        plain, vector = (min(timed(f, 2000) for _ in range(3)) for f in (world._clearance_small, world._clearance_numpy))
        print(f"exact clearance among {n:2d} things: plain floats {plain:5.1f} us, NumPy {vector:5.1f} us")
    clear, sweep = exact_us(*yard, 3000)
    print(f"exact geometry in the crowded yard: clearance {clear:6.1f} us, swept test {sweep:6.1f} us "
          f"(= {clear / base:.1f}x and {sweep / base:.1f}x a plain step)")
    with tempfile.TemporaryDirectory() as folder:  # the corridor without its walls: the same run, nothing to touch
        bare = Path(folder) / "corridor_bare.yaml"
        bare.write_text(yaml.safe_dump({k: v for k, v in corridor.data.items() if k != "walls"}))
        rtf_bare = max(patrol_rtf(str(bare)) for _ in range(3))
        rtf_walls = max(patrol_rtf(str(REPO / "worlds" / "corridor.yaml")) for _ in range(3))
        rtf_person = max(patrol_rtf(str(REPO / "worlds" / "corridor_person.yaml")) for _ in range(3))
    print(f"patrol real-time factor (best of 3): corridor without walls {rtf_bare:5.0f}x, with its walls "
          f"{rtf_walls:5.0f}x (ratio {rtf_walls / rtf_bare:.2f}), with the pacing person giving way "
          f"{rtf_person:5.0f}x (ratio {rtf_person / rtf_bare:.2f})")
    figures.put("clearance_crowded_us", clear)
    figures.put("swept_crowded_us", sweep)
    figures.put("rtf.corridor_bare", rtf_bare)
    figures.put("rtf.corridor", rtf_walls)
    figures.put("rtf.corridor_person", rtf_person)
    figures.save()


if __name__ == "__main__":
    main()
