"""Line following, the detector's cost, the simulator with the camera on, and the live video server.

Run from the repository root (a measurement, not a test; nothing asserts)::

    python benchmarks/line_following.py [--seeds 10] [--stream-seconds 8]

Prints:

1. A full lap of ``worlds/line_track.yaml`` at 0.15 m/s for each seed
   (``follow_line: {speed: 0.15 m/s, until: {distance: <lap length>}}``):
   the fraction of time the robot's centre is within 5 cm of the line (goal
   >= 0.95, the field's bar 0.90), the p95 error, and the intersections
   detected against those passed, with false detections (goal: all
   detected, none false) -- all from the run summary's ``truth``.
2. The line detector's cost per frame at 320x240 and 640x480 (goal < 3 ms at
   320x240), on frames rendered along the track, against the naive tutorial
   pipeline of ``benchmarks/naive_line.py`` on the same frames (the anchor,
   timed interleaved frame by frame in the same run; medians of 5 passes
   with their spread).
3. The simulator's real-time factor with the camera on (the laps above; goal
   >= 20), against the patrol mission with the camera off (the baseline).
4. The streaming server at 1280x720, 25 fps, 3 viewers (separate processes on
   127.0.0.1), one deliberately slow: the sustained frame rate it encodes and
   each viewer receives, the server process's CPU share, and the cost of
   ``publish`` on the tick loop's side.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
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
from beastbt.live.video_stream import StreamConfig, VideoStreamServer  # noqa: E402
from beastbt.sim.camera_emulator import CameraEffects, SimCamera  # noqa: E402
from beastbt.sim.floor import FloorMap  # noqa: E402
from beastbt.sim.truth import RobotTruth  # noqa: E402
from beastbt.vision.camera_model import CameraGeometry  # noqa: E402
from beastbt.vision.line_detector import LineDetector, LineDetectorConfig  # noqa: E402

sys.path.insert(0, str(REPO / "benchmarks"))
from figures import Figures  # noqa: E402  (benchmarks/figures.py)
from naive_line import interleaved_passes, spread  # noqa: E402

WORLD = REPO / "worlds" / "line_track.yaml"
PATROL = REPO / "missions" / "patrol.yaml"
SPEED_MPS = 0.15


def loop_length_m(floor: FloorMap) -> float:
    """Length of the track's closed loop (its first path), metres."""
    segs = floor.lines[0].segments()
    return float(np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1).sum())


def poses_along_loop(floor: FloorMap, n: int) -> list[tuple[float, float, float]]:
    """``n`` poses on the loop's centreline, heading along it."""
    segs = floor.lines[0].segments()
    lengths = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    out = []
    for s in np.linspace(0.0, cum[-1], n, endpoint=False):
        i = int(np.searchsorted(cum, s, side="right")) - 1
        a, b = segs[i]
        p = a + (s - cum[i]) / lengths[i] * (b - a)
        out.append((float(p[0]), float(p[1]), math.atan2(b[1] - a[1], b[0] - a[0])))
    return out


def run_quiet(mission: str, seed: int) -> dict:
    """One run at full speed, no run folder; the summary."""
    p = prepare(mission, RunOptions(seed=seed, record=False))
    with open(os.devnull, "w") as devnull:
        return execute(p, devnull)


# -- 1 and 3: laps -----------------------------------------------------------------------------

def laps(seeds: int, floor: FloorMap) -> list[dict]:
    lap = loop_length_m(floor)
    with tempfile.TemporaryDirectory() as tmp:
        mission = Path(tmp) / "lap.yaml"
        mission.write_text(yaml.safe_dump({
            "mission": "line_track_lap", "world": str(WORLD),
            "steps": [{"follow_line": {"speed": f"{SPEED_MPS} m/s", "until": {"distance": f"{lap:.3f} m"}}}]}))
        print(f"1. a full lap of line_track ({lap:.2f} m of loop) at {SPEED_MPS} m/s, follow_line until that distance")
        print(f"   {'seed':>4} {'status':>8} {'within 5 cm':>11} {'p95 cm':>7} {'max cm':>7} "
              f"{'junctions passed/detected/false':>32} {'sim s':>6} {'wall s':>7} {'RTF':>6}")
        out = []
        for seed in range(1, seeds + 1):
            s = run_quiet(str(mission), seed)
            t = s["truth"]
            rtf = s["sim_time_s"] / s["wall_time_s"]
            out.append({**t, "status": s["status"], "rtf": rtf, "sim_s": s["sim_time_s"], "wall_s": s["wall_time_s"],
                        "true_distance_m": s["distance_m"]})
            print(f"   {seed:>4} {s['status']:>8} {t['line_within_5cm_frac']:>11.3f} {t['line_error_p95_m'] * 100:>7.2f} "
                  f"{t['line_error_max_m'] * 100:>7.2f} {t['intersections_passed']:>18}/{t['intersections_detected']}/"
                  f"{t['false_intersections']:<11} {s['sim_time_s']:>6.1f} {s['wall_time_s']:>7.2f} {rtf:>6.1f}")
    ok = sum(r["status"] == "success" for r in out)
    within = [r["line_within_5cm_frac"] for r in out]
    p95 = [r["line_error_p95_m"] for r in out]
    passed = sum(r["intersections_passed"] for r in out)
    detected = sum(r["intersections_detected"] for r in out)
    false = sum(r["false_intersections"] for r in out)
    print(f"   => {ok}/{len(out)} laps completed; time within 5 cm: mean {statistics.mean(within):.3f}, worst "
          f"{min(within):.3f} (goal >= 0.95); p95 error: mean {statistics.mean(p95) * 100:.2f} cm, worst "
          f"{max(p95) * 100:.2f} cm")
    print(f"   => intersections: {detected} detected of {passed} passed, {false} false detections "
          f"(goal: all detected, none false); true path length per lap {statistics.mean(r['true_distance_m'] for r in out):.2f} m")
    FIGURES.put("laps.completed", ok)
    FIGURES.put("laps.within_5cm_mean", statistics.mean(within))
    FIGURES.put("laps.within_5cm_worst", min(within))
    FIGURES.put("laps.p95_cm_mean", statistics.mean(p95) * 100)
    FIGURES.put("laps.p95_cm_worst", max(p95) * 100)
    FIGURES.put("laps.intersections_missed", passed - detected)
    FIGURES.put("laps.false_intersections", false)
    return out


# -- 2: the detector's cost ------------------------------------------------------------------------

FIGURES = Figures("line_following")
"""The figures this run prints, saved at its end for benchmarks/check_docs.py (benchmarks/figures.py)."""


def detector_cost(floor: FloorMap, frames: int = 300, reps: int = 5) -> None:
    print(f"\n2. line detector cost per frame (frames rendered along the loop, default camera effects; {frames} frames,"
          f" median of {reps} passes (min-max))")
    print(f"   {'size':>9} {'detect ms':>20} {'naive ms (anchor)':>20} {'detect/naive':>18}")
    poses = poses_along_loop(floor, frames)
    for w, h in ((320, 240), (640, 480)):
        geom = CameraGeometry(width_px=w, height_px=h)
        cam = SimCamera(floor, geom, np.random.default_rng(1), CameraEffects())
        det = LineDetector(LineDetectorConfig(), geom)
        images = []
        for x, y, yaw in poses:
            cam.update(RobotTruth(x=x, y=y, yaw=yaw, v_mps=SPEED_MPS))
            images.append(cam.read()[1])
        naive_passes, detect_passes, ratios = interleaved_passes(images, det, reps)
        print(f"   {w}x{h:<5} {spread(detect_passes):>20} {spread(naive_passes):>20} {spread(ratios):>17}x")
        FIGURES.spread(f"detector.size{w}x{h}.detect_ms", detect_passes)
        FIGURES.spread(f"detector.size{w}x{h}.naive_ms", naive_passes)
        FIGURES.spread(f"detector.size{w}x{h}.ratio", ratios)
    print("   (goal: under 3 ms per frame at 320x240)")


# -- 3: the simulator with the camera on ----------------------------------------------------------------

def real_time_factor(lap_runs: list[dict], seeds: int) -> None:
    base = [run_quiet(str(PATROL), seed) for seed in range(1, min(seeds, 3) + 1)]
    base_rtf = statistics.median(s["sim_time_s"] / s["wall_time_s"] for s in base)
    cam_rtf = statistics.median(r["rtf"] for r in lap_runs)
    print("\n3. simulator real-time factor (sim seconds per wall second, whole runs)")
    print(f"   camera on (15 fps 320x240 rendered + detected, line_track laps): median {cam_rtf:.1f}x, "
          f"worst {min(r['rtf'] for r in lap_runs):.1f}x (goal >= 20)")
    print(f"   camera off (patrol mission, the baseline): median {base_rtf:.1f}x; ratio on/off {cam_rtf / base_rtf:.2f}")
    FIGURES.put("rtf.camera_on", cam_rtf)
    FIGURES.put("rtf.camera_off", base_rtf)
    FIGURES.put("rtf.ratio", cam_rtf / base_rtf)


# -- 4: the streaming server -------------------------------------------------------------------------------

VIEWER = r"""
import json, socket, sys, time
port, limit_s, slow = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3] == "1"
s = socket.socket()
if slow:
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8192)
s.connect(("127.0.0.1", port))
s.settimeout(5.0)
s.sendall(b"GET /stream.mjpg HTTP/1.0\r\n\r\n")
mark, tail, frames, total = b"--beastbtframe", b"", 0, 0
t0 = time.monotonic()
first = last = None
while time.monotonic() - t0 < limit_s:   # bounded; normally ends when the server closes the stream
    try:
        data = s.recv(16384 if slow else 262144)
    except socket.timeout:
        break
    if not data:
        break
    total += len(data)
    chunk = tail + data
    n = chunk.count(mark) - tail.count(mark)
    if n:
        now = time.monotonic()
        first = now if first is None else first
        last = now
        frames += n
    tail = chunk[-(len(mark) - 1):]
    if slow:
        time.sleep(0.05)   # a viewer on a slow link: about 300 kB/s
span = (last - first) if first is not None and last is not None else 0.0
print(json.dumps({"frames": frames, "bytes": total, "span_s": span}))
"""


def stream_benchmark(floor: FloorMap, seconds: float) -> None:
    w, h, fps = 1280, 720, 25.0
    print(f"\n4. live video server: {w}x{h} JPEG q80 with overlay, {fps:g} fps, 3 viewers (one slow) for {seconds:g} s")
    geom = CameraGeometry(width_px=w, height_px=h)
    cam = SimCamera(floor, geom, np.random.default_rng(2), CameraEffects())
    det = LineDetector(LineDetectorConfig(), geom)
    frames = []
    for i, (x, y, yaw) in enumerate(poses_along_loop(floor, 50)):
        cam.update(RobotTruth(x=x, y=y, yaw=yaw, v_mps=SPEED_MPS))
        image = cam.read()[1]
        frames.append((image, det.detect_full(image, i / fps)))
    server = VideoStreamServer(StreamConfig(port=0, width_px=w, height_px=h, jpeg_quality=80, fps=fps)).start()
    server.set_status({"mission": "benchmark", "status": "running", "step": "follow line until intersection", "time_s": 0.0})
    viewers = [subprocess.Popen([sys.executable, "-c", VIEWER, str(server.port), str(seconds + 30), "1" if k == 2 else "0"],
                                stdout=subprocess.PIPE, text=True) for k in range(3)]
    for _ in range(500):  # bounded: until the three are connected
        if server.client_count == 3:
            break
        time.sleep(0.01)
    publish_us = []
    encoded0, encode_s0 = server.frames_encoded, server.encode_s
    ru0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    k = 0
    while time.perf_counter() - t0 < seconds:  # the camera: a new frame every 1/fps s
        image, detection = frames[k % len(frames)]
        a = time.perf_counter()
        server.publish(image, k / fps, detection, geom, 0.25)
        publish_us.append((time.perf_counter() - a) * 1e6)
        k += 1
        time.sleep(max(0.0, t0 + k / fps - time.perf_counter()))
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_SELF)
    encoded = server.frames_encoded - encoded0
    encode_ms = (server.encode_s - encode_s0) / max(1, encoded) * 1e3
    clients = sorted(server.clients(), key=lambda c: c.address)
    server.close()  # ends every viewer's stream
    results = []
    for v in viewers:
        out, _ = v.communicate(timeout=60)
        results.append(json.loads(out))
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    print(f"   published {k / wall:.1f} fps; encoded {encoded / wall:.1f} fps sustained "
          f"({encode_ms:.1f} ms per frame to scale, draw and encode)")
    for i, r in enumerate(results):
        kind = "slow" if i == 2 else "fast"
        span = max(r["span_s"], 1e-9)
        print(f"   viewer {i + 1} ({kind}): {(r['frames'] - 1) / span:.1f} fps received over {span:.1f} s, "
              f"{r['bytes'] / span / 1e6:.2f} MB/s")
    print("   server side: " + "; ".join(f"{c.frames} sent, {c.skipped} skipped" for c in clients))
    print(f"   server process CPU: {cpu / wall * 100:.0f} % of one core ({cpu / wall / os.cpu_count() * 100:.0f} % of the "
          f"{os.cpu_count()}-core machine)")
    print(f"   publish() on the tick loop's side: median {statistics.median(publish_us):.1f} us, "
          f"max {max(publish_us):.1f} us (never waits for a viewer)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--stream-seconds", type=float, default=8.0)
    args = parser.parse_args()
    world = yaml.safe_load(WORLD.read_text())
    floor = FloorMap.from_dict(world["floor"], np.random.default_rng(0))
    lap_runs = laps(args.seeds, floor)
    detector_cost(floor)
    real_time_factor(lap_runs, args.seeds)
    stream_benchmark(floor, args.stream_seconds)
    FIGURES.save()


if __name__ == "__main__":
    main()
