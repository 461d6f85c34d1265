"""What decoding the LiDARs costs: microseconds per revolution and share of a core at the model's rate.

Builds the bytes of a stream of revolutions in memory (an LD19 at 10 Hz,
4500 points/s: 37.5 packets per turn; an RPLIDAR A1 at 5.5 Hz, 2000
samples/s: 364 samples per turn), feeds them to the real drivers through an
in-memory port in 10 ms reads, and prints per revolution the driver's time
and, as the baseline measured in the same run, the time of bare
``struct.unpack`` of the same bytes (the least any Python decoder does); the
ratio is what framing, checks, resync, masking and assembling cost on top.
The LD19 is also fed in 50 ms reads (what the run loop's 20 Hz tick reads).
Goal of issue 20 for the whole chain (decode + costmap + monitor): at most
0.5 ms per 10 Hz scan. ``--cpu`` times with this thread's CPU time instead of
the wall clock (on a shared machine the wall clock counts other processes).

Run: python benchmarks/lidar_decode.py [--revolutions 200] [--cpu]
"""

from __future__ import annotations

import argparse
import struct
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from beastbt.core.clock import SimClock  # noqa: E402
from beastbt.devices.ld19 import Ld19Lidar, crc8  # noqa: E402
from beastbt.devices.lidar_scan import LidarConfig  # noqa: E402
from beastbt.devices.rplidar import RplidarA1  # noqa: E402
from lidar_support import MemorySerial as Port  # noqa: E402 - the tests' in-memory port


def ld19_stream(revolutions: int) -> bytes:
    out = bytearray()
    step = 3600.0 / 4500.0  # degrees per point at 10 Hz
    angle = 0.0
    for i in range(int(revolutions * 4500 / 10 / 12)):
        start, end = angle % 360.0, (angle + 11 * step) % 360.0
        body = struct.pack("<BBHH", 0x54, 0x2C, 3600, int(start * 100))
        body += b"".join(struct.pack("<HB", 1500 + (i + k) % 500, 200) for k in range(12))
        body += struct.pack("<HH", int(end * 100), (i * 3) % 30000)
        out += body + bytes([crc8(body)])
        angle += 12 * step
    return bytes(out)


def a1_stream(revolutions: int) -> bytes:
    out = bytearray()
    per_rev = 364
    for rev in range(revolutions):
        for k in range(per_rev):
            q6 = int(k * 360.0 / per_rev * 64)
            s = 1 if k == 0 else 0
            out += bytes(((40 << 2) | ((1 - s) << 1) | s, ((q6 & 0x7F) << 1) | 1, q6 >> 7))
            out += struct.pack("<H", (1500 + k) * 4)
    return bytes(out)


TIMER = time.perf_counter
"""What the figures are timed with (``--cpu``: time.thread_time)."""


def run(driver, port: Port, clock: SimClock, wire: bytes, chunk: int, dt: float = 0.01) -> tuple[float, int]:
    scans = 0
    t0 = TIMER()
    for i in range(0, len(wire), chunk):
        port.rx += wire[i:i + chunk]
        clock.advance(dt)
        scans += len(driver.poll())
    return TIMER() - t0, scans


def baseline(wire: bytes, fmt: str) -> float:
    unpack = struct.Struct(fmt)
    t0 = TIMER()
    for offset in range(0, len(wire) - unpack.size + 1, unpack.size):
        unpack.unpack_from(wire, offset)
    return TIMER() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--revolutions", type=int, default=200)
    parser.add_argument("--cpu", action="store_true", help="time with this thread's CPU time, not the wall clock")
    args = parser.parse_args()
    global TIMER
    TIMER = time.thread_time if args.cpu else time.perf_counter
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("lidar_decode")
    n = args.revolutions

    wire = ld19_stream(n)
    clock, port = SimClock(), Port()
    driver = Ld19Lidar(port, clock, config=LidarConfig.from_dict({"type": "ld19"}))
    spent, scans = run(driver, port, clock, wire, chunk=230400 // 10 // 100)  # 10 ms of bytes
    base = baseline(wire, "<BBHH" + "HB" * 12 + "HHB")
    per = spent / max(1, scans)
    print(f"LD19 at 10 Hz, 10 ms reads: {scans} scans of {driver.stats.points_per_scan} points; {per * 1e6:.0f} us "
          f"per revolution ({per * 10 * 100:.2f} % of a core); bare struct.unpack {base / max(1, scans) * 1e6:.0f} us "
          f"(ratio {spent / base:.1f})")
    figures.put("ld19.us", per * 1e6)
    figures.put("ld19.pct", per * 10 * 100)
    figures.put("ld19.unpack_ratio", spent / base)
    clock, port = SimClock(), Port()
    driver = Ld19Lidar(port, clock, config=LidarConfig.from_dict({"type": "ld19"}))
    spent, scans = run(driver, port, clock, wire, chunk=230400 // 10 // 20, dt=0.05)  # a 20 Hz tick's bytes
    per = spent / max(1, scans)
    print(f"LD19 at 10 Hz, 50 ms reads (the 20 Hz tick): {per * 1e6:.0f} us per revolution "
          f"({per * 10 * 100:.2f} % of a core); ratio to bare struct.unpack {spent / base:.1f}")
    figures.put("ld19_50ms_reads.us", per * 1e6)
    figures.put("ld19_50ms_reads.pct", per * 10 * 100)

    wire = a1_stream(n)
    clock, port = SimClock(), Port()
    driver = RplidarA1(port, clock, config=LidarConfig.from_dict({"type": "rplidar_a1"}))
    # Past the start-up sequence (STOP, GET_HEALTH, GET_INFO, SCAN): only the samples are timed.
    driver._opened = True
    driver.state = "scanning"
    spent, scans = run(driver, port, clock, wire, chunk=115200 // 10 // 100)
    base = baseline(wire, "<BBBH")
    per = spent / max(1, scans)
    print(f"RPLIDAR A1 at 5.5 Hz: {scans} scans of {driver.stats.points_per_scan} points; {per * 1e6:.0f} us per "
          f"revolution ({per * 5.5 * 100:.2f} % of a core); bare struct.unpack {base / max(1, scans) * 1e6:.0f} us "
          f"(ratio {spent / base:.1f})")
    figures.put("a1.us", per * 1e6)
    figures.put("a1.pct", per * 5.5 * 100)
    figures.save()


if __name__ == "__main__":
    main()
