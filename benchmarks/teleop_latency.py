"""Teleop latency and watchdog reaction in real time, for each base adapter.

Not a test: runs the real tick loop (``beastbt.run.session.execute``) on
the wall clock at 20 Hz with the real joystick driver, teleop hook, mux,
safety gate, watchdog thread and each base adapter (Waveshare serial JSON
through pyserial on a pseudo-terminal to the firmware fake of the tests,
``tests/fake_waveshare.py``, as on the robot's UART; CAN through python-can's
virtual bus; PWM on an emulated PCA9685), and prints:

1. the latency from a joystick event (its 8 bytes becoming readable, as the
   kernel would make them) to the first command that carries the new speed
   where the device sees it (for the Waveshare base: when the firmware fake
   has read and parsed the JSON line from its end of the pty; for CAN: the
   frame on the bus; for PWM: the chip's last register written): p50 / p99 /
   max, with the joystick watcher waking the
   loop on input (as on the robot) and, as the baseline measured in the same
   run, without it (the wait for the next 20 Hz tick, ~U(0, 50 ms)).
   Goal (issue 12): p99 < 10 ms.
2. the time from a frozen tick loop (a hook that blocks mid-tick) to the
   watchdog's zero on the wire, measured from the last command the loop
   wrote. Goal: <= 0.55 s.

Run: python benchmarks/teleop_latency.py [--events 120] [--freezes 5] [--adapters waveshare,can,pwm]
"""

from __future__ import annotations

import argparse
import io
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Callable, Optional

import can
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))
from fake_waveshare import FakeWaveshare  # noqa: E402  (the firmware fake on a pty, shared with the tests)

from beastbt.actuation.can_base import CanBase, CanBaseConfig
from beastbt.actuation.pwm_base import PwmBase, PwmBaseConfig
from beastbt.devices.joystick import JS_EVENT, JS_EVENT_AXIS, JS_EVENT_BUTTON, JS_EVENT_INIT, JoystickDevice, JoystickMapping, JoystickWatcher
from beastbt.devices.pca9685 import Pca9685
from beastbt.devices.waveshare_base import WaveshareBase
from beastbt.mission.model import load_mission
from beastbt.core.clock import WallClock
from beastbt.core.events import EventLog
from beastbt.robot.hardware import open_serial
from beastbt.robot.profile import load_profile
from beastbt.robot.robot_io import RobotIO
from beastbt.run.runner import MissionRun
from beastbt.run.session import RunOptions, execute
from beastbt.assembly import assemble
from beastbt.parts.teleop import TeleopPart
from beastbt.robot.part import REAL
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.pca9685_emulator import SimPca9685

RATE_HZ = 20.0
PROFILE = """
robot: bench
geometry: {track_width_m: 0.2}
limits: {max_speed_mps: 0.5, max_turn_rate_dps: 180, max_accel_mps2: 1.0}
base: {type: BASE}
"""
MISSION = "mission: bench\nrate: 20 Hz\nsteps:\n  - wait: 1 h\n"
LOW, HIGH = 0.2, 0.6
"""Stick positions alternated between events: 0.1 and 0.3 m/s at teleop's 0.5 m/s scale."""


class Writes:
    """Timestamped payloads an adapter wrote (perf_counter seconds)."""

    def __init__(self) -> None:
        self.items: list[tuple[float, object]] = []
        self.lock = threading.Lock()

    def add(self, payload: object, t: Optional[float] = None) -> None:
        """Record ``payload`` as written at perf_counter time ``t`` (default: now)."""
        t = time.perf_counter() if t is None else t
        with self.lock:
            self.items.append((t, payload))

    def snapshot(self) -> list[tuple[float, object]]:
        with self.lock:
            return list(self.items)


class PipeJoystick:
    """A joystick whose events the benchmark writes into a pipe from another thread, read like /dev/input/js0.

    The read end is non-blocking and has a ``fileno``, as the real device's
    source does, so the run's joystick watcher wakes the loop on input.
    """

    def __init__(self, mapping: JoystickMapping) -> None:
        self.mapping = mapping
        self.r, self.w = os.pipe()
        os.set_blocking(self.r, False)
        self.t0 = time.perf_counter()

    def opener(self) -> Callable[[], Callable[[], bytes]]:
        def open_device() -> Callable[[], bytes]:
            burst = b"".join(JS_EVENT.pack(0, 0, JS_EVENT_BUTTON | JS_EVENT_INIT, n) for n in range(12))
            burst += b"".join(JS_EVENT.pack(0, 0, JS_EVENT_AXIS | JS_EVENT_INIT, n) for n in range(8))
            os.write(self.w, burst)

            def read() -> bytes:
                return self.read()
            read.fileno = lambda: self.r  # type: ignore[attr-defined]
            return read
        return open_device

    def read(self) -> bytes:
        try:
            return os.read(self.r, 4096)
        except BlockingIOError:
            return b""

    def emit(self, kind: int, number: int, value: int) -> float:
        """Make one event readable now; return the perf_counter time it became readable."""
        ms = int((time.perf_counter() - self.t0) * 1000) & 0xFFFFFFFF
        t = time.perf_counter()
        os.write(self.w, JS_EVENT.pack(ms, value, kind, number))
        return t

    def stick(self, linear: float) -> float:
        number, inverted = self.mapping.axes()["linear"]
        return self.emit(JS_EVENT_AXIS, number, self.mapping.raw_for(linear, inverted))

    def button(self, name: str, pressed: bool) -> float:
        return self.emit(JS_EVENT_BUTTON, self.mapping.buttons()[name], 1 if pressed else 0)


class TimedBus:
    """python-can bus wrapper that timestamps every frame the adapter sends."""

    def __init__(self, bus: can.BusABC, writes: Writes) -> None:
        self.bus = bus
        self.writes = writes

    def send(self, msg: can.Message, timeout: Optional[float] = None) -> None:
        self.bus.send(msg, timeout=timeout)
        self.writes.add(bytes(msg.data))

    def recv(self, timeout: Optional[float] = None) -> Optional[can.Message]:
        return self.bus.recv(timeout=timeout)

    def shutdown(self) -> None:
        self.bus.shutdown()


class TimedPca(SimPca9685):
    """The emulated chip; a write to the last register of channel 1 completes one velocity command."""

    def __init__(self, writes: Writes) -> None:
        super().__init__()
        self.timed = writes

    def on_write(self, register: int, value: int) -> None:
        if register == 0x0D:
            self.timed.add(bytes(self.registers[0x06:0x0E]))


def build_base(kind: str, writes: Writes, closers: list[Callable[[], object]]) -> tuple[object, Callable[[object], bool]]:
    """(adapter, is_zero(payload)) for one adapter kind, writes timestamped into ``writes``; what must be closed
    after the run is appended to ``closers``."""
    if kind == "waveshare":
        fake = FakeWaveshare("ros").__enter__()
        closers.append(lambda: fake.__exit__(None, None, None))
        port = open_serial("base", fake.port, 115200, "the fake's pty")
        closers.append(port.close)
        stop = threading.Event()
        # The fake stamps each command on time.monotonic when it read it; move them to perf_counter's scale.
        offset = time.perf_counter() - time.monotonic()

        def collect() -> None:
            seen = 0
            while not stop.is_set():
                with fake._lock:
                    fresh = fake.received[seen:]
                seen += len(fresh)
                for t, command in fresh:
                    if command.get("T") == 1:
                        writes.add((command.get("L"), command.get("R")), t + offset)
                time.sleep(0.001)

        collector = threading.Thread(target=collect, name="bench-collect", daemon=True)
        collector.start()
        closers.append(lambda: (stop.set(), collector.join(1.0)))
        return WaveshareBase(port), lambda p: p == (0.0, 0.0)
    if kind == "can":
        channel = f"beastbt-bench-{os.getpid()}-{time.perf_counter_ns()}"
        cfg = CanBaseConfig(interface="virtual", channel=channel, feedback_kind="none")
        bus = TimedBus(can.Bus(interface="virtual", channel=channel, receive_own_messages=False), writes)
        return CanBase(bus, cfg), lambda p: p == bytes(4)  # type: ignore[arg-type]
    if kind == "pwm":
        i2c = SimI2CBus()
        chip = TimedPca(writes)
        i2c.attach(0x40, chip)
        neutral: dict = {}

        def is_zero(p: object) -> bool:
            return p == neutral.get("payload")

        base = PwmBase(Pca9685(i2c), PwmBaseConfig())
        base.start(0.0)
        neutral["payload"] = bytes(chip.registers[0x06:0x0E])
        return base, is_zero
    raise ValueError(kind)


def percentile(xs: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(xs), q)) if xs else float("nan")


def run_adapter(kind: str, n_events: int, n_freezes: int, seed: int, wake: bool = True) -> dict:
    """Drive one adapter through the real loop; return latencies and freeze reactions (seconds)."""
    rng = np.random.default_rng(seed)
    tmp = Path(tempfile.mkdtemp(prefix="beastbt-bench-"))
    base_type = {"waveshare": "waveshare_serial", "can": "can", "pwm": "pwm"}[kind]
    (tmp / "robot.yaml").write_text(PROFILE.replace("BASE", base_type))
    profile = load_profile(tmp / "robot.yaml")
    mission = load_mission(str(tmp / "m.yaml"), text=MISSION)
    writes = Writes()
    closers: list[Callable[[], object]] = []
    base, is_zero = build_base(kind, writes, closers)
    clock = WallClock()
    events = EventLog(clock)
    mapping = JoystickMapping()
    pad = PipeJoystick(mapping)
    device = JoystickDevice(pad.opener(), clock, events.sink("joystick"), mapping)
    ticks: list[float] = []
    io_ = RobotIO(base=base)  # type: ignore[arg-type]
    io_.sensors["tick"] = lambda now: ticks.append(time.perf_counter()) or []
    io_.sensors["joystick"] = lambda now: [device.poll()]
    io_.joystick = device
    io_.capabilities.add("joystick")
    if wake:  # as on the robot: input wakes the loop between ticks
        io_.joystick_watcher = JoystickWatcher(device, io_.wakeup.set).start()
        io_.closers.append(io_.joystick_watcher.stop)
    duration_s = 2.0 + n_events * 0.4 + n_freezes * 2.0 + 5.0
    options = RunOptions(robot="bench", record=False, speed="realtime", max_time_s=duration_s)
    # The same assembly as a run on the robot, around this bench's base and gamepad: the run wires the watchdog.
    prepared = assemble(mission, profile, options, REAL, io=io_, clock=clock, parts=[TeleopPart()])
    run = prepared.run
    events = prepared.events
    dog = run.watchdog

    freeze = threading.Event()
    resume = threading.Event()
    blocked_at: list[float] = []

    def freezer(run_: MissionRun, now_s: float) -> None:
        if freeze.is_set():
            blocked_at.append(time.perf_counter())
            resume.wait(5.0)
            freeze.clear()
            resume.clear()

    run.hooks.append(freezer)
    stick_events: list[float] = []
    freezes: list[tuple[float, float, float]] = []
    done = threading.Event()

    def operator() -> None:
        time.sleep(0.5)
        pad.button("enable", True)
        pad.stick(LOW)
        time.sleep(0.5)
        value = LOW
        for _ in range(n_events):
            time.sleep(float(rng.uniform(0.25, 0.4)))  # random phase against the 50 ms ticks
            value = HIGH if value == LOW else LOW
            stick_events.append(pad.stick(value))
        time.sleep(0.5)
        for _ in range(n_freezes):
            time.sleep(0.6)  # moving at a steady speed again
            freeze.set()
            deadline = time.perf_counter() + 2.0
            while not blocked_at or (freezes and blocked_at[-1] <= freezes[-1][1]):
                time.sleep(0.001)
            t_block = blocked_at[-1]
            zero_t = None
            while time.perf_counter() < deadline and zero_t is None:
                for t, p in writes.snapshot():
                    if t > t_block and is_zero(p):
                        zero_t = t
                        break
                time.sleep(0.005)
            last_loop = max(t for t, _ in writes.snapshot() if t <= t_block)
            freezes.append((last_loop, t_block, zero_t if zero_t is not None else float("nan")))
            resume.set()
        time.sleep(0.3)
        run.finish("success", "benchmark done")
        done.set()

    threading.Thread(target=operator, daemon=True).start()
    try:
        execute(prepared, io.StringIO())
        done.wait(5.0)
    finally:
        for close in reversed(closers):
            close()

    items = writes.snapshot()
    lat, wait, proc = [], [], []
    for te in stick_events:
        before = [p for t, p in items if t < te]
        after = [(t, p) for t, p in items if t >= te]
        if not before or not after:
            continue
        steady = before[-1]
        hit = next(((t, p) for t, p in after if p != steady), None)
        if hit is None:
            continue
        lat.append(hit[0] - te)
        tick = next((t for t in ticks if t >= te), None)
        if tick is not None and tick <= hit[0]:
            wait.append(tick - te)
            proc.append(hit[0] - tick)
    return {"kind": kind, "lat": lat, "wait": wait, "proc": proc, "freezes": freezes, "trips": dog.trips,
            "ticks": run.ticks}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=120, help="stick events per adapter (default 120)")
    parser.add_argument("--freezes", type=int, default=5, help="frozen-loop trials per adapter (default 5)")
    parser.add_argument("--adapters", default="waveshare,can,pwm")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    period_ms = 1000.0 / RATE_HZ
    print(f"teleop latency in real time at {RATE_HZ:g} Hz (tick period {period_ms:.0f} ms), {os.cpu_count()} CPUs")
    print("joystick event -> first adapter bytes carrying the new command (ms); goal (issue 12): p99 < 10 ms with the")
    print("joystick watcher waking the loop; 'tick only' is the same run without it (the baseline: the next 20 Hz tick)")
    print(f"{'adapter':10s} {'mode':10s} {'n':>4s} {'p50':>7s} {'p99':>7s} {'max':>7s} | p99/period")
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("teleop_latency")
    results = []
    for kind in args.adapters.split(","):
        for wake in (True, False):
            r = run_adapter(kind.strip(), args.events, args.freezes if wake else 0, args.seed, wake=wake)
            if wake:
                results.append(r)
            ms = lambda xs, q: 1000.0 * percentile(xs, q)  # noqa: E731
            print(f"{r['kind']:10s} {'wake' if wake else 'tick only':10s} {len(r['lat']):4d} {ms(r['lat'], 50):7.1f} "
                  f"{ms(r['lat'], 99):7.1f} {1000 * max(r['lat'], default=float('nan')):7.1f} | "
                  f"{ms(r['lat'], 99) / period_ms:.2f}")
            key = f"{r['kind']}.{'wake' if wake else 'tick_only'}"
            figures.put(f"{key}.p50_ms", ms(r["lat"], 50))
            figures.put(f"{key}.p99_ms", ms(r["lat"], 99))
    print()
    print("frozen tick loop -> watchdog zero on the wire (s); goal <= 0.55 s")
    print(f"{'adapter':10s} {'n':>4s} {'from last cmd: mean':>20s} {'max':>6s} | {'from freeze: mean':>18s} {'max':>6s} | trips")
    for r in results:
        fz = r["freezes"]
        from_cmd = [z - c for c, _, z in fz]
        from_freeze = [z - b for _, b, z in fz]
        print(f"{r['kind']:10s} {len(fz):4d} {np.mean(from_cmd):20.3f} {np.max(from_cmd):6.3f} | "
              f"{np.mean(from_freeze):18.3f} {np.max(from_freeze):6.3f} | {r['trips']}")
        figures.put(f"{r['kind']}.freeze.from_cmd_max_s", float(np.max(from_cmd)))
        figures.put(f"{r['kind']}.freeze.from_freeze_max_s", float(np.max(from_freeze)))
    figures.save()


if __name__ == "__main__":
    main()
