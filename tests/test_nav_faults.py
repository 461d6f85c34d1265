"""Device faults injected through the emulators during a run: each shows up in the run's events, none crashes it."""

from __future__ import annotations

import pynmea2

from nav_support import events_of, harness, place_yaml

GO_TO_A = f"""
mission: t
places:
  a: {place_yaml(0.0, 14.0)}
steps:
  - go_to: {{place: a, gps_timeout: 20 s}}
"""


def test_garbage_truncated_lines_and_bad_checksums_are_reported_and_skipped(tmp_path):
    h = harness(tmp_path, GO_TO_A)
    h.tick(100)
    port = h.run.io.sim_gps.port
    good = str(pynmea2.GGA("GP", "GGA", ("120005.000", "4722.6140", "N", "00832.5020", "E", "1", "09", "0.90",
                                         "410.0", "M", "0.0", "M", "", "")))
    bad_checksum = good[:-2] + ("00" if good[-2:] != "00" else "11")
    port.feed(b"\x00\xff\xfe binary noise \x13\x37\r\n")
    port.feed(bad_checksum.encode() + b"\r\n")
    port.feed(good[:25].encode() + b"\r\n")
    h.tick(5)
    k = [e.kind for e in h.events]
    assert "gps_garbage" in k and "gps_checksum" in k and "gps_no_checksum" in k
    stats = h.run.io.gps_driver.stats
    assert stats.rejected["garbage"] >= 1 and stats.rejected["checksum"] == 1
    fixes = stats.fixes
    assert h.run_to_end(timeout_s=200) == "success"
    assert h.run.io.gps_driver.stats.fixes > fixes        # it kept reading after the bad bytes


def test_a_vanished_gps_port_is_reopened_and_the_run_carries_on(tmp_path):
    h = harness(tmp_path, GO_TO_A)
    h.tick(200)                                        # 10 s in, driving
    gps = h.run.io.sim_gps
    gps.port.unplug()
    h.tick(40)
    lost = events_of(h, "gps_port_lost")
    assert len(lost) == 1 and "position goes stale" in lost[0].text
    assert h.run.io.gps_driver.is_stale(h.now_s)
    assert h.result is None                            # still running on dead reckoning
    gps.port.replug()
    assert h.tick_until(lambda h: bool(events_of(h, "gps_port_reopened")), timeout_s=5)
    assert h.run_to_end(timeout_s=200) == "success"
    assert not events_of(h, "device_error")


def test_a_missing_imu_is_reported_and_the_run_goes_on_without_it(tmp_path):
    h = harness(tmp_path, GO_TO_A)
    h.run.io.imu_bus.detach(0x68)           # no MPU9250 answers on the bus
    assert h.run_to_end(timeout_s=200) == "success"
    missing = events_of(h, "imu_missing")
    assert missing and "no MPU9250 answers" in missing[0].text
    assert h.run.io.imu_tap.count == 0        # nothing from the MPU9250 (the base's own IMU goes on)
    assert not events_of(h, "device_error")


def test_a_wrong_who_am_i_is_reported(tmp_path):
    h = harness(tmp_path, GO_TO_A, imu={"whoami": 0x70})
    assert h.run_to_end(timeout_s=200) == "success"
    wrong = events_of(h, "imu_wrong_id")
    assert wrong and "WHO_AM_I 0x70" in wrong[0].text
    assert h.run.io.imu_tap.count == 0


def test_i2c_errors_make_the_imu_stale_then_it_comes_back(tmp_path):
    h = harness(tmp_path, GO_TO_A)
    h.tick(100)
    tap = h.run.io.imu_tap
    assert tap.count > 90
    bus = h.run.io.imu_bus
    bus.fail_next = 40                                  # every transfer fails for a while
    h.tick(30)
    assert events_of(h, "imu_i2c_error") and events_of(h, "imu_lost")
    assert h.now_s - tap.last.stamp_s > 1.0             # no fresh MPU9250 samples meanwhile: stale
    assert h.tick_until(lambda h: h.now_s - tap.last.stamp_s < 0.1, timeout_s=5)
    assert events_of(h, "imu_reinit")
    assert h.run_to_end(timeout_s=200) == "success"
    assert not events_of(h, "device_error")


def test_the_profile_can_set_the_receiver_to_5_hz_at_start(tmp_path):
    from beastbt.testing import MissionHarness
    from conftest import REPO
    from nav_support import write_world
    profile = tmp_path / "robot.yaml"
    text = (REPO / "robots" / "sim.yaml").read_text()
    profile.write_text(text.replace("  port_baud: 9600", "  port_baud: 9600\n  rate_hz: 5"))
    h = MissionHarness.from_yaml(GO_TO_A, robot=str(profile), world=write_world(tmp_path), base_dir=tmp_path)
    h.tick(41)
    assert h.run.io.sim_gps.rate_hz == 5.0                 # PMTK220,200 reached the receiver
    assert h.run.io.gps_driver.pending_acks == {}          # and its PMTK001 came back
    assert not [e for e in h.events if e.kind.startswith("gps_config")]
    epochs = {r.time_utc for rec in h.records for r in rec.readings if type(r).__name__ == "GpsFix"}
    assert len(epochs) >= 10                                          # 2 s at 5 Hz
    assert h.run_to_end(timeout_s=200) == "success"
