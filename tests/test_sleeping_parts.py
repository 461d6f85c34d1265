"""A part that the run does not use costs nothing per tick (issue 11, 8d).

The GPS, the IMU and the EKF sleep when nothing in the run reads what they
fill: not the tree's leaves, not its conditions, not the failsafes or
``on_failure``, not another awake part (a recording reads nothing itself:
``--record-sensors`` keeps them all awake).
Sleeping parts are neither polled, nor emulated, nor fused; the mission
itself runs exactly as it would with them awake.
"""

from __future__ import annotations

import pytest

from beastbt.robot.part import Part, asleep
from beastbt.testing import MissionHarness
from conftest import REPO

PATROL_LIKE = "mission: t\nworld: corridor.yaml\nsteps:\n  - drive: {distance: 1 m, speed: 0.2 m/s}\n  - wait: 1 s\n"


def harness(text: str, **options) -> MissionHarness:
    return MissionHarness.from_yaml(text, base_dir=REPO / "worlds", seed=3, **options)


def close(h: MissionHarness) -> None:
    for closer in h.prepared.closers:
        closer()


def awake(h: MissionHarness) -> dict[str, bool]:
    """Which of the GPS, IMU and EKF do work on every tick of ``h``'s run."""
    io = h.run.io
    emulators = io.sim.emulators
    return {"gps": "gps" in io.sensors and any(e.__qualname__.startswith("attach_sim_gps") for e in emulators),
            "imu": "imu" in io.sensors and any(e.__qualname__.startswith("_sampler") for e in emulators),
            "ekf": h.run.estimator is not None}


def lidar_awake(h: MissionHarness) -> bool:
    """True when the LiDAR (robots/sim.yaml's LD19) is polled and ray-cast on every tick of ``h``'s run."""
    io = h.run.io
    return "lidar" in io.sensors and any(type(getattr(e, "__self__", None)).__name__ == "SimLd19"
                                         for e in io.sim.emulators)


def test_a_mission_that_only_drives_leaves_gps_imu_and_ekf_asleep():
    h = harness(PATROL_LIKE)
    assert awake(h) == {"gps": False, "imu": False, "ekf": False}
    assert lidar_awake(h)  # the collision monitor below the tree reads every scan, whatever the mission does
    assert any(e.kind == "asleep" and e.text.endswith("gps, imu, navigation") for e in h.events)
    assert h.run_to_end() == "success"
    assert h.blackboard("gps_fix") is None  # (the base's own IMU still reports: the base is always awake)
    assert h.blackboard("pose").position_valid is False


def test_a_recorded_run_keeps_where_it_was_and_lets_the_rest_sleep(tmp_path):
    from beastbt.recording.track import PositionTrack
    h = harness(PATROL_LIKE, record_path=str(tmp_path / "run.mcap"))
    # The recording reads the GPS fix (where the robot was); the EKF steps for it about once a second only.
    assert awake(h) == {"gps": True, "imu": False, "ekf": True}
    track = h.run.estimator
    assert isinstance(track, PositionTrack) and track.period_s == 1.0
    assert lidar_awake(h)  # the collision monitor reads it (and /scan is recorded)
    assert h.run_to_end() == "success"
    close(h)
    seconds = h.run.elapsed_s
    # At least once a second (the fused pose recorded at >= 1 Hz), at most once per GPS epoch (1 Hz) and per second.
    assert seconds > 5 and seconds - 1 <= track.steps <= 2 * seconds + 3


def test_record_sensors_keeps_them_awake(tmp_path):
    h = harness(PATROL_LIKE, record_path=str(tmp_path / "run.mcap"), record_sensors=True)
    assert awake(h) == {"gps": True, "imu": True, "ekf": True}
    assert not any(e.kind == "asleep" for e in h.events)
    h.run_to_end()
    close(h)


def test_record_sensors_without_a_recording_wakes_nothing():
    h = harness(PATROL_LIKE, record_sensors=True)  # the harness records nothing
    assert awake(h) == {"gps": False, "imu": False, "ekf": False}


@pytest.mark.parametrize("steps, expected", [
    ("- turn: {heading: 90 deg}", {"gps": True, "imu": True, "ekf": True}),           # reads the fused pose
    ("- wait_until: gps_fix", {"gps": True, "imu": False, "ekf": False}),               # a condition on the fix alone
    ("- wait_until: {near: home, within: 2 m}", {"gps": True, "imu": True, "ekf": True}),
    ("- {if: {battery_below: 11 V}, then: [wait: 1 s]}", {"gps": False, "imu": False, "ekf": False}),
])
def test_what_the_tree_reads_wakes_what_fills_it(steps, expected):
    h = harness(f"mission: t\nworld: campus.yaml\nsteps:\n  {steps}\n")
    assert awake(h) == expected


@pytest.mark.parametrize("extra", [
    "failsafes:\n  geofence: {center: home, radius: 50 m, then: stop}\n",
    "on_failure: return_home\n",
])
def test_failsafes_and_on_failure_wake_the_fused_pose(extra):
    h = harness(PATROL_LIKE + extra)
    assert awake(h) == {"gps": True, "imu": True, "ekf": True}


def test_gps_lost_wakes_the_gps_only():
    h = harness(PATROL_LIKE + "failsafes:\n  gps_lost: {after: 3 s, then: hold}\n")
    assert awake(h) == {"gps": True, "imu": False, "ekf": False}


def test_sleeping_changes_nothing_the_mission_does(tmp_path):
    """The same seed drives the same way whether the GPS, IMU and EKF sleep or not (each emulator has its own noise)."""
    quiet, loud = harness(PATROL_LIKE), harness(PATROL_LIKE, record_path=str(tmp_path / "run.mcap"))
    sent_quiet, sent_loud = [], []
    for h, sent in ((quiet, sent_quiet), (loud, sent_loud)):
        while h.tick() is None:
            sent.append((h.run.last_sent.linear_mps, h.run.last_sent.angular_rps))
        truth = h.run.io.sim.truth
        sent.append((truth.x, truth.y, truth.yaw))
    close(loud)
    assert sent_quiet == sent_loud


class _Fake(Part):
    def __init__(self, name: str, fills=(), reads=(), can_sleep=True) -> None:
        self.name, self.fills, self.reads = name, tuple(fills), tuple(reads)  # type: ignore[misc]
        if can_sleep:
            self.sleep = lambda prepared: None  # type: ignore[method-assign]

    def overrides(self, hook: str) -> bool:
        return hook == "sleep" and "sleep" in self.__dict__


def test_asleep_follows_what_awake_parts_read_transitively():
    gps = _Fake("gps", fills=["gps_fix"])
    imu = _Fake("imu", fills=["imu"])
    ekf = _Fake("ekf", fills=["pose"], reads=["gps_fix", "imu"])
    lonely = _Fake("lonely", fills=["thing"])
    recorder = _Fake("recorder", reads=["pose"], can_sleep=False)
    parts = [gps, imu, ekf, lonely]
    assert asleep(parts, ()) == parts
    assert asleep(parts, ("pose",)) == [lonely]
    assert asleep(parts, ("imu",)) == [gps, ekf, lonely]
    assert asleep(parts + [recorder], ()) == [lonely]
