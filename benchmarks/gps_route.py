"""The A to B to C GPS route on the simulator: how much the fusion beats raw GPS, and how fast the simulator is.

For each seed it runs ``missions/gps_route.yaml`` in ``worlds/campus.yaml``
(an MTK3339 in open sky) with the emulated GPS and IMU read by the real
drivers and fused by the EKF, and prints, measured in the same run:

1. the fused RMS position error against the raw GPS RMS error, both against
   the simulator's truth (goal: fused at most 0.4 times raw), and whether
   every waypoint was reached;
2. the heading error at the end of a 10 s GPS dropout while driving (the same
   route without its gps_lost failsafe, the GPS silent from 400 s to 410 s on
   the way home; goal: under 3 deg), and for comparison the same with the
   emulated magnetometer fused (the sim robot's EKF does not use it);
3. the largest move of the fused position caused by a single injected 20 m
   GPS jump (one epoch at 250 s, on the way from b to c), measured against a
   twin run of the same seed without the jump (goal: under 1 m);
4. the simulator's real-time factor on the route (goal: at least 100).

Run: python benchmarks/gps_route.py [--seeds 10] [--default-noise-seeds 3] [--no-magnetometer-comparison]
"""

from __future__ import annotations

import argparse
import io
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.estimation.estimator import wrap_angle  # noqa: E402
from beastbt.assembly import prepare  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402

MISSION = REPO / "missions" / "gps_route.yaml"
WORLD = REPO / "worlds" / "campus.yaml"
DROPOUT_S = (400.0, 410.0)
"""The GPS is silent in this window of the dropout runs (on the way home), s."""
JUMP_AT_S = 250.0
JUMP_M = 20.0
"""One epoch of the GPS 20 m off at this time (on the way from b to c), s and m."""


class Trace:
    """Per tick: time, fused position in the world frame (m), fused and true yaw, truth (m), validity."""

    def __init__(self, frame) -> None:
        self.frame = frame
        self.rows: list[tuple] = []

    def __call__(self, rec) -> None:
        pose, truth = rec.pose, rec.truth
        if pose is None or truth is None or not pose.position_valid or pose.lat is None:
            return
        e, n, _ = self.frame.to_enu(pose.lat, pose.lon, None)
        self.rows.append((rec.now_s, e, n, pose.yaw, pose.heading_valid, truth.x, truth.y, truth.yaw, truth.v_mps))


def run(seed: int, mission: Path = MISSION, world: Path = WORLD, jump: bool = False,
        robot: str = "sim") -> tuple[dict, Trace, float]:
    """One run; returns its summary, its trace and the wall time of the loop (s)."""
    p = prepare(str(mission), RunOptions(seed=seed, world=str(world), robot=robot, record=False,
                                         simulate=True))
    trace = Trace(p.world.frame)
    p.run.recorders.append(trace)
    if jump:
        angle = 2.0 * math.pi * ((seed * 0.618034) % 1.0)  # a different direction per seed, reproducible
        p.run.io.sim_gps.inject_jump(JUMP_M * math.cos(angle), JUMP_M * math.sin(angle), JUMP_AT_S, 1.0)
    t0 = time.perf_counter()
    summary = execute(p, io.StringIO())
    return summary, trace, time.perf_counter() - t0


def write_variant(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--default-noise-seeds", type=int, default=3,
                    help="also run this many seeds with the emulator's default GPS noise (2 m wandering bias)")
    ap.add_argument("--no-magnetometer-comparison", action="store_true",
                    help="skip the dropout runs with the magnetometer fused (for comparison)")
    args = ap.parse_args()
    seeds = list(range(1, args.seeds + 1))
    tmp = Path(tempfile.mkdtemp(prefix="beastbt-bench-"))
    world_doc = yaml.safe_load(WORLD.read_text())

    # 1 and 4: the route as written
    print(f"1. missions/gps_route.yaml in worlds/campus.yaml, {len(seeds)} seeds")
    fused_sq = raw_sq = 0.0
    fused_n = raw_n = 0
    factors, all_reached = [], True
    for seed in seeds:
        s, trace, wall = run(seed)
        t = s["truth"]
        reached = all(w["reached"] for w in s["waypoints"]) and len(s["waypoints"]) == 4
        all_reached &= reached and s["status"] == "success"
        factors.append(s["sim_time_s"] / wall)
        # pool squared errors over all runs (each run's RMS weighted by its samples)
        fused_sq += t["position_error_rms_m"] ** 2 * len(trace.rows)
        fused_n += len(trace.rows)
        raw_sq += t["gps_error_rms_m"] ** 2 * t["gps_fixes"]
        raw_n += t["gps_fixes"]
        errors = ", ".join(f"{w['name']} {w['arrival_error_m']:.2f}" for w in s["waypoints"] if w["reached"])
        print(f"   seed {seed:2d}: {s['status']:7s} fused {t['position_error_rms_m']:.2f} m, raw GPS "
              f"{t['gps_error_rms_m']:.2f} m (ratio {t['position_error_rms_m'] / t['gps_error_rms_m']:.2f}), "
              f"heading {t['heading_error_rms_deg']:.1f} deg rms; arrivals (m): {errors}")
    fused, raw = math.sqrt(fused_sq / fused_n), math.sqrt(raw_sq / raw_n)
    print(f"   fused RMS {fused:.2f} m vs raw GPS RMS {raw:.2f} m: ratio {fused / raw:.2f} (goal <= 0.4); "
          f"every waypoint reached in every run: {'yes' if all_reached else 'NO'}")

    if args.default_noise_seeds:
        doc = dict(world_doc)
        doc["gps"] = {"cold_start_s": 1.0}  # the emulator's own MTK3339 defaults: 1.5 m white, 2 m bias (60 s)
        w = write_variant(tmp, "campus_default_gps.yaml", yaml.safe_dump(doc))
        ratios = []
        for seed in range(1, args.default_noise_seeds + 1):
            s, _, _ = run(seed, world=w)
            ratios.append(s["truth"]["position_error_rms_m"] / s["truth"]["gps_error_rms_m"])
        print(f"   for comparison, with the emulator's default noise (mostly a slowly wandering 2 m bias, which no "
              f"fusion with odometry can see): ratio {statistics.mean(ratios):.2f} over {len(ratios)} seeds")

    # 2: heading after a 10 s dropout while driving
    print(f"2. heading error after a {DROPOUT_S[1] - DROPOUT_S[0]:g} s GPS dropout while driving "
          f"({DROPOUT_S[0]:g}-{DROPOUT_S[1]:g} s, no gps_lost failsafe)")
    doc = dict(world_doc)
    doc["gps"] = dict(doc["gps"], dropouts_s=[list(DROPOUT_S)])
    w = write_variant(tmp, "campus_dropout.yaml", yaml.safe_dump(doc))
    mission_text = MISSION.read_text().split("failsafes:")[0] + "on_failure: stop\n"
    m = write_variant(tmp, "gps_route_no_failsafe.yaml", mission_text.replace("../worlds/campus.yaml", str(WORLD)))

    def dropout_runs(robot: str, verbose: bool) -> tuple[list[float], list[float]]:
        at_end, at_start = [], []
        for seed in seeds:
            _, trace, _ = run(seed, mission=m, world=w, robot=robot)
            window = [r for r in trace.rows if DROPOUT_S[0] <= r[0] < DROPOUT_S[1]]
            if not window:
                print(f"   seed {seed:2d}: the run ended before the dropout")
                continue
            last, first = window[-1], window[0]
            at_end.append(abs(math.degrees(wrap_angle(last[3] - last[7]))))
            at_start.append(abs(math.degrees(wrap_angle(first[3] - first[7]))))
            if verbose:
                speed = statistics.mean(r[8] for r in window)
                print(f"   seed {seed:2d}: heading error {at_start[-1]:.2f} deg when the GPS went, {at_end[-1]:.2f} "
                      f"deg 10 s later; mean true speed meanwhile {speed:.2f} m/s")
        return at_end, at_start

    # The dropout runs use the sim robot without its compass: the harder case, where the
    # heading comes from the GPS track alone. The comparison below fuses the compass.
    no_mag = (REPO / "robots" / "sim.yaml").read_text().replace("use_magnetometer: true", "use_magnetometer: false")
    at_end, at_start = dropout_runs(str(write_variant(tmp, "sim_without_magnetometer.yaml", no_mag)), True)
    print(f"   after the dropout: mean {statistics.mean(at_end):.2f} deg, worst {max(at_end):.2f} deg, "
          f"{sum(e < 3.0 for e in at_end)} of {len(at_end)} under 3 deg (goal < 3 deg); before it: mean "
          f"{statistics.mean(at_start):.2f} deg. Without the compass in the EKF the "
          f"heading comes from the GPS track and course at 0.2 m/s, and the gyro carries it through the dropout.")
    if not args.no_magnetometer_comparison:
        profile = (REPO / "robots" / "sim.yaml").read_text()
        marker = "\nestimator:"
        assert marker in profile
        profile = profile.replace("use_magnetometer: true", "use_magnetometer: true\n  declination_deg: "
                                  f"{world_doc['imu']['mag_declination_deg']}", 1)
        robot = write_variant(tmp, "sim_with_magnetometer.yaml", profile)
        mag_end, _ = dropout_runs(str(robot), False)
        print(f"   for comparison, the same runs with the emulated (undisturbed) magnetometer fused: mean "
              f"{statistics.mean(mag_end):.2f} deg, worst {max(mag_end):.2f} deg after the dropout")

    # 3: a single 20 m jump
    print(f"3. a single {JUMP_M:g} m GPS jump (one epoch at {JUMP_AT_S:g} s): largest move of the fused position "
          "against a twin run without it")
    moves = []
    for seed in seeds:
        _, base, _ = run(seed)
        _, jumped, _ = run(seed, jump=True)
        by_t = {round(r[0], 3): r for r in base.rows}
        move = 0.0
        for r in jumped.rows:
            if JUMP_AT_S - 1.0 <= r[0] <= JUMP_AT_S + 20.0:
                b = by_t.get(round(r[0], 3))
                if b is not None:
                    move = max(move, math.hypot(r[1] - b[1], r[2] - b[2]))
        moves.append(move)
        print(f"   seed {seed:2d}: fused position moved by at most {move:.3f} m")
    print(f"   worst {max(moves):.3f} m, mean {statistics.mean(moves):.3f} m (goal < 1 m)")

    # 4: speed
    print(f"4. real-time factor on the route: median {statistics.median(factors):.0f}x, "
          f"min {min(factors):.0f}x (goal >= 100x; wall time of the loop, loading excluded)")
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("gps_route")
    figures.put("fused_rms_m", fused)
    figures.put("raw_gps_rms_m", raw)
    figures.put("fused_raw_ratio", fused / raw)
    figures.put("all_reached", int(all_reached))
    figures.put("dropout.heading_after_mean_deg", statistics.mean(at_end))
    figures.put("dropout.heading_after_worst_deg", max(at_end))
    figures.put("jump.worst_move_m", max(moves))
    figures.put("jump.mean_move_m", statistics.mean(moves))
    figures.put("realtime_factor.median", statistics.median(factors))
    figures.put("realtime_factor.min", min(factors))
    figures.put("seeds", len(seeds))
    figures.save()


if __name__ == "__main__":
    main()
