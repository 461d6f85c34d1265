"""The simulator's CPU accounting (beastbt/sim/cpu_account.py): brackets charge each kind its own thread CPU time,
the robot's work inside the simulator is not the simulator's, the totals file holds what the process charged,
and a simulated run charges the physics and each awake emulator."""

from __future__ import annotations

import io
import time

from conftest import REPO

from beastbt.sim import cpu_account
from beastbt.sim.cpu_account import (BASE, CAMERA, GPS, IMU, KINDS, LIDAR, PHYSICS, ROBOT, SIM_CPU, SPLIT, SimCpu,
                                     kind_of, read_totals)


def burn(seconds: float) -> None:
    """Spend about ``seconds`` of this thread's CPU."""
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


def test_nested_brackets_charge_each_kind_its_own_time_and_nothing_outside():
    account = SimCpu()
    account.enable()
    burn(0.01)  # outside every bracket: charged to nobody
    outer = account.enter(LIDAR)
    burn(0.03)
    inner = account.enter(ROBOT)  # the robot's work called from the simulator
    burn(0.02)
    account.leave(inner)
    burn(0.01)
    account.leave(outer)
    burn(0.01)
    seconds = account.seconds()
    assert 0.039 <= seconds["lidar"] < 0.06
    assert 0.019 <= seconds["robot"] < 0.03
    assert account.simulator_s() == seconds["lidar"]  # the robot's is not the simulator's
    assert seconds["gps"] == 0.0


def test_a_split_bracket_shares_its_own_time_by_the_weights_given():
    account = SimCpu()
    account.enable()
    outer = account.enter(SPLIT)
    burn(0.04)
    account.call(ROBOT, burn, 0.02)  # nested: charged to itself, not shared out
    weights = [0.0] * len(KINDS)
    weights[PHYSICS], weights[LIDAR] = 1.0, 3.0
    account.leave_split(outer, weights)
    seconds = account.seconds()
    assert 0.039 <= seconds["physics"] + seconds["lidar"] < 0.06
    assert abs(seconds["lidar"] - 3 * seconds["physics"]) < 1e-9
    assert 0.019 <= seconds["robot"] < 0.03


def test_nothing_is_charged_while_off():
    account = SimCpu()
    outer = account.enter(LIDAR)
    burn(0.01)
    account.leave(outer)
    assert account.seconds()["lidar"] == 0.0


def test_the_totals_file_holds_what_the_process_charged(tmp_path):
    account = SimCpu()
    account.enable()
    account.call(GPS, burn, 0.01)  # charged before the file exists: carried over
    account.open_file(str(tmp_path))  # (turns it on too)
    account.call(CAMERA, burn, 0.01)
    (path,) = tmp_path.iterdir()
    totals = read_totals(path)
    assert totals == [account.seconds()[kind] for kind in cpu_account.KINDS]
    assert totals[GPS] >= 0.009 and totals[CAMERA] >= 0.009


def test_the_environment_opens_the_totals_file_only_where_the_simulator_is_built(tmp_path, monkeypatch):
    monkeypatch.delenv(cpu_account.ENV_DIR, raising=False)
    account = SimCpu()
    account.open_from_environment()
    assert not account.enabled and not list(tmp_path.iterdir())  # no folder named: it stays off
    monkeypatch.setenv(cpu_account.ENV_DIR, str(tmp_path))
    account.open_from_environment()
    account.open_from_environment()  # the second call keeps the file the first opened
    account.call(IMU, burn, 0.01)
    (path,) = tmp_path.iterdir()
    assert account.enabled and read_totals(path)[IMU] >= 0.009


def test_kinds_of_emulators_and_of_the_robots_own_work():
    from beastbt.actuation.watchdog import AdapterWatchdog
    from beastbt.sim.waveshare_emulator import SimWaveshareBase

    assert kind_of(SimWaveshareBase.update) == BASE
    assert kind_of(AdapterWatchdog.on_physics_step) == ROBOT
    assert kind_of(lambda now_s, dt_s: None) == cpu_account.OTHER


def _patrol(seconds: float, accounted: bool) -> tuple[dict, dict, float]:
    """(summary, seconds charged per kind, the loop thread's CPU s) of the unrecorded patrol at full speed."""
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute

    was = SIM_CPU.enabled
    SIM_CPU.enabled = accounted
    try:
        prepared = prepare(str(REPO / "missions" / "patrol.yaml"),
                           RunOptions(speed="max", max_time_s=seconds, record=False))
        before = SIM_CPU.seconds()
        cpu0 = time.thread_time()
        summary = execute(prepared, out=io.StringIO())
        loop_cpu = time.thread_time() - cpu0
    finally:
        SIM_CPU.enabled = was
    return summary, {kind: SIM_CPU.seconds()[kind] - before[kind] for kind in before}, loop_cpu


def test_a_simulated_run_charges_the_physics_the_emulators_and_the_watchdog_apart():
    summary, charged, loop_cpu = _patrol(20.0, accounted=True)
    assert summary["ticks"] == 401
    # The patrol's awake emulators: the ESP32 base and the LiDAR (read by the collision monitor); its GPS and IMU
    # sleep (nothing reads them), and nothing renders its camera.
    assert charged["physics"] > 0 and charged["base"] > 0 and charged["lidar"] > 0
    assert charged["gps"] == charged["imu"] == charged["camera"] == 0.0
    assert charged["robot"] > 0  # the watchdog checked at every physics step
    simulator = sum(v for kind, v in charged.items() if kind != "robot")
    assert simulator < loop_cpu  # the tree, the drivers, the estimator, safety are not the simulator's


def test_accounting_changes_nothing_of_the_run_and_charges_nothing_when_off():
    accounted, _, _ = _patrol(8.0, accounted=True)
    plain, charged, _ = _patrol(8.0, accounted=False)
    assert all(v == 0.0 for v in charged.values())
    for key in ("ticks", "distance_m", "truth"):
        assert accounted[key] == plain[key]
