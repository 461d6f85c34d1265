"""The RPLIDAR A1 driver against a fake A1 on a pseudo-terminal (request/response, samples of a synthetic room)."""

from __future__ import annotations

import os
import random
import time

import numpy as np
import serial

from beastbt.core.clock import SimClock, WallClock
from beastbt.devices.lidar_scan import LidarConfig
from beastbt.devices.rplidar import RplidarA1
from fake_rplidar import FakeRplidar, descriptor, scan_sample
from lidar_support import MemorySerial, poll_until, range_errors

STOP, RESET, SCAN, GET_INFO, GET_HEALTH = 0x25, 0x40, 0x20, 0x50, 0x52


def open_driver(fake: FakeRplidar, events: list | None = None, **config) -> tuple[RplidarA1, serial.Serial]:
    port = serial.Serial(fake.port, 115200, timeout=0)
    sink = (lambda kind, text: events.append((kind, text))) if events is not None else (lambda kind, text: None)
    driver = RplidarA1(port, WallClock(), sink, config=LidarConfig.from_dict({"type": "rplidar_a1", **config}))
    return driver, port


def good_fraction(scan, fake) -> float:
    return float(np.mean(range_errors(scan, fake.truth_m) < 0.003))


def test_the_driver_asks_health_info_then_scans_and_the_ranges_match_the_room():
    events: list = []
    with FakeRplidar(rate_hz=5.5) as fake:
        driver, port = open_driver(fake, events)
        scans = poll_until(driver, lambda s: len(s) >= 4, timeout_s=4.0)
        driver.close()
        time.sleep(0.05)
        assert not fake.scanning  # close() said STOP
    assert fake.requests[:4] == [STOP, GET_HEALTH, GET_INFO, SCAN]
    assert fake.requests[-1] == STOP
    assert driver.health is not None and driver.health.status == 0 and driver.health.text == "good"
    info = driver.info
    assert info is not None and info.model == 0x18 and info.firmware == "1.29" and info.hardware == 7
    assert info.serial_hex == bytes(range(0x10, 0x20)).hex().upper() and info.model_name == "A1M8"
    assert len(scans) >= 4
    for scan in scans:
        assert 340 <= len(scan) <= 390  # 2000 samples/s at 5.5 Hz
        assert good_fraction(scan, fake) > 0.98
        assert np.ptp(np.degrees(scan.angles_rad)) > 355
    assert abs(scans[-1].scan_rate_hz - 5.5) < 0.3
    assert driver.stats.crc_failures == 0
    # A pty has no DTR: the driver said so once and went on.
    assert driver.dtr_works is False and [k for k, _ in events].count("lidar_no_dtr") == 1


def test_the_fake_only_streams_after_scan_and_stops_at_stop():
    with FakeRplidar() as fake:
        port = serial.Serial(fake.port, 115200, timeout=0)
        time.sleep(0.15)
        assert port.read(4096) == b""  # a one-way stream it is not
        port.write(bytes((0xA5, SCAN)))
        time.sleep(0.15)
        got = port.read(4096)
        assert got[:7] == descriptor(5, 1, 0x81) and len(got) > 7 + 5 * 100
        port.write(bytes((0xA5, STOP)))
        time.sleep(0.05)
        port.read(65536)
        time.sleep(0.1)
        assert port.read(4096) == b""
        port.close()


def test_garbage_is_skipped_and_decoding_resumes():
    rng = random.Random(3)
    with FakeRplidar() as fake:
        driver, port = open_driver(fake)
        poll_until(driver, lambda s: len(s) >= 1, timeout_s=3.0)
        for _ in range(5):
            fake.inject(bytes(rng.randrange(256) for _ in range(37)))
            time.sleep(0.03)
        scans = poll_until(driver, lambda s: len(s) >= 3, timeout_s=3.0)
        driver.close()
    assert len(scans) >= 3
    assert driver.stats.garbage_bytes > 0 and driver.stats.crc_failures >= 1
    assert all(good_fraction(s, fake) > 0.97 for s in scans)


def test_bad_check_bits_are_counted_and_dropped():
    with FakeRplidar() as fake:
        driver, port = open_driver(fake)
        poll_until(driver, lambda s: len(s) >= 1, timeout_s=3.0)
        fake.bad_samples_next = 5
        scans = poll_until(driver, lambda s: len(s) >= 3, timeout_s=3.0)
        driver.close()
    assert driver.stats.crc_failures >= 1
    for scan in scans:
        assert not np.any(np.abs(scan.ranges_m - 7.777) < 0.001)  # the bad samples said 7.777 m


def answer_sequence(port: MemorySerial, driver: RplidarA1, clock: SimClock) -> None:
    """Walk the in-memory device through STOP, GET_HEALTH, GET_INFO and SCAN as the A1 answers them."""
    driver.poll()
    assert bytes(port.written) == bytes((0xA5, STOP))
    clock.advance(0.01)
    driver.poll()
    assert bytes(port.written[-2:]) == bytes((0xA5, GET_HEALTH))
    port.feed(descriptor(3, 0, 0x06) + bytes((0, 0, 0)))
    driver.poll()
    assert bytes(port.written[-2:]) == bytes((0xA5, GET_INFO))
    port.feed(descriptor(20, 0, 0x04) + bytes((0x18, 29, 1, 7)) + bytes(16))
    driver.poll()
    assert bytes(port.written[-2:]) == bytes((0xA5, SCAN))
    port.feed(descriptor(5, 1, 0x81))
    driver.poll()
    assert driver.state == "scanning"


def test_samples_split_at_every_byte_decode_the_same_and_dtr_drives_the_motor():
    clock = SimClock()
    port = MemorySerial()
    driver = RplidarA1(port, clock, config=LidarConfig.from_dict({"type": "rplidar_a1"}))
    answer_sequence(port, driver, clock)
    assert port.dtr_changes == [False]  # DTR cleared = motor on (Slamtec SDK)
    wire = b""
    for rev in range(4):
        for k in range(360):
            wire += scan_sample(k == 0, 40, k * 1.0, 1000.0 + k)
    scans = []
    for i, byte in enumerate(wire):
        port.feed(bytes([byte]))
        if i % 50 == 0:
            clock.advance(0.005)  # 36 steps of 5 ms per revolution: a 5.6 Hz head
        scans += driver.poll()
    # The first S opens revolution 1 and closes nothing; the next three close revolutions 1-3; the 4th is open.
    assert driver.stats.crc_failures == 0 and driver.stats.garbage_bytes == 0
    assert [len(s) for s in scans] == [360, 360, 360]
    assert np.allclose(scans[-1].ranges_m, (1000.0 + np.arange(360)) / 1000.0)
    driver.close()
    assert port.dtr_changes == [False, True] and bytes(port.written[-2:]) == bytes((0xA5, STOP))


def test_whole_revolutions_come_out_at_the_measured_rate():
    clock = SimClock()
    port = MemorySerial()
    driver = RplidarA1(port, clock, config=LidarConfig.from_dict({"type": "rplidar_a1"}))
    answer_sequence(port, driver, clock)
    scans = []
    for rev in range(5):
        for k in range(360):
            port.feed(scan_sample(k == 0, 40, k * 1.0, 2000.0))
            if k % 36 == 35:
                clock.advance(0.02)  # 10 reads of 20 ms per revolution: 5 Hz
                scans += driver.poll()
    assert len(scans) == 4  # the first S opens revolution 1; revolutions 1-4 are closed by the next S
    assert all(len(s) == 360 for s in scans)
    assert abs(scans[-1].scan_rate_hz - 5.0) < 0.01
    assert np.allclose(scans[-1].ranges_m, 2.0)


def test_a_motor_not_at_speed_gives_no_scans_until_it_is():
    events: list = []
    with FakeRplidar(spinup_s=0.8) as fake:
        driver, port = open_driver(fake, events)
        early = poll_until(driver, lambda s: False, timeout_s=0.6)
        assert early == [] and driver.state == "scanning" and driver.is_stale(driver._clock.now())
        assert driver.stats.spinup_packets > 100  # quality-0 samples without an S bit were dropped
        scans = poll_until(driver, lambda s: len(s) >= 2, timeout_s=3.0)
        driver.close()
    assert len(scans) >= 2 and all(good_fraction(s, fake) > 0.98 for s in scans)


def test_a_silent_device_goes_stale_is_asked_again_and_comes_back():
    events: list = []
    with FakeRplidar() as fake:
        driver, port = open_driver(fake, events, stale_after_s=0.3, reopen_interval_s=0.3)
        poll_until(driver, lambda s: len(s) >= 1, timeout_s=3.0)
        assert not driver.is_stale(driver._clock.now())
        asked = len(fake.requests)
        fake.silent = True
        poll_until(driver, lambda s: False, timeout_s=0.8)
        assert driver.is_stale(driver._clock.now())
        assert len(fake.requests) == asked  # silent: it did not even read them
        fake.silent = False
        scans = poll_until(driver, lambda s: len(s) >= 1, timeout_s=3.0)
        assert scans and not driver.is_stale(driver._clock.now())
        driver.close()
    assert driver.is_stale(driver._clock.now())  # closed: no port, no scans
    assert fake.requests[asked:asked + 4] == [STOP, GET_HEALTH, GET_INFO, SCAN] or SCAN in fake.requests[asked:]
    kinds = [k for k, _ in events]
    assert kinds.count("lidar_silent") == 1 and kinds.index("lidar_silent") < kinds.index("lidar_back")


def test_a_device_in_error_is_reset_once_and_then_scans():
    events: list = []
    with FakeRplidar(health=(2, 0x8001)) as fake:
        driver, port = open_driver(fake, events)
        scans = poll_until(driver, lambda s: len(s) >= 1, timeout_s=4.0)
        driver.close()
    assert RESET in fake.requests and fake.requests.count(RESET) == 1
    assert scans and driver.health is not None and driver.health.status == 0
    assert any(k == "lidar_health_error" and "0x8001" in t for k, t in events)


def test_pty_modem_lines_cannot_be_observed():
    # Why the fake cannot see DTR (documented in fake_rplidar): a pty has no modem control lines.
    import fcntl
    import termios
    master, slave = os.openpty()
    try:
        for fd in (master, slave):
            try:
                fcntl.ioctl(fd, termios.TIOCMGET, b"\0" * 4)
            except OSError:
                continue
            raise AssertionError("this kernel's pty has modem lines: the fake could observe DTR")
    finally:
        os.close(master)
        os.close(slave)


def test_a_head_turning_below_the_minimum_rate_gives_no_scans():
    clock = SimClock()
    port = MemorySerial()
    driver = RplidarA1(port, clock, config=LidarConfig.from_dict({"type": "rplidar_a1", "min_rate_hz": 2.0}))
    answer_sequence(port, driver, clock)
    scans = []
    for rev in range(4):
        for k in range(360):
            port.feed(scan_sample(k == 0, 40, k * 1.0, 2000.0))
            if k % 36 == 35:
                clock.advance(0.1)  # one revolution a second: 1 Hz, below 2 Hz
                scans += driver.poll()
    assert scans == [] and driver.stats.spinup_packets >= 360 * 2


def test_a_port_that_fails_is_reopened():
    events: list = []
    clock = SimClock()
    first, second = MemorySerial(), MemorySerial()
    opened = []

    def reopen():
        opened.append(clock.now())
        return second

    driver = RplidarA1(first, clock, lambda k, t: events.append(k), open_port=reopen,
                       config=LidarConfig.from_dict({"type": "rplidar_a1", "reopen_interval_s": 1.0}))
    driver.poll()

    def broken(size: int = 1) -> bytes:
        raise OSError("device reports readiness to read but returned no data")
    first.feed(b"x")
    first.read = broken  # type: ignore[method-assign]
    driver.poll()
    assert not driver.port_open and "lidar_port_lost" in events and driver.is_stale(clock.now())
    clock.advance(0.5)
    driver.poll()
    assert opened == []  # not before reopen_interval_s
    clock.advance(0.6)
    driver.poll()
    assert opened and driver.port_open and "lidar_port_reopened" in events
    assert second.dtr_changes == [False] and bytes(second.written[:2]) == bytes((0xA5, STOP))  # started again


def test_how_the_samples_are_cut_into_reads_does_not_change_the_scans():
    # Aligned runs of samples are taken at once (NumPy), breaks go sample by sample: reads of one byte, of a
    # few samples or of everything must give the same scans and counts, and the same as the sample-by-sample
    # loop alone (the reference: the driver with its aligned runs turned off).
    rng = random.Random(11)
    wire = bytearray()
    for rev in range(6):
        for k in range(300):
            sample = bytearray(scan_sample(k == 0, 0 if k % 37 == 0 else 40, k * 1.2, 800.0 + (rev * 300 + k) % 900))
            if rng.random() < 0.01:
                sample[1] ^= 1  # a bad check bit
            wire += sample
            if rng.random() < 0.01:
                wire += bytes(rng.randrange(256) for _ in range(rng.randrange(1, 9)))  # garbage between samples
    results = []
    for size, one_by_one in ((115, True), (1, False), (17, False), (115, False), (len(wire), False)):
        clock, port = SimClock(), MemorySerial()
        driver = RplidarA1(port, clock, config=LidarConfig.from_dict({"type": "rplidar_a1"}))
        if one_by_one:
            driver._aligned_run = lambda buf, pos, now_s, scans: pos  # type: ignore[method-assign]
        answer_sequence(port, driver, clock)
        scans = []
        for i in range(0, len(wire), size):
            chunk = bytes(wire[i:i + size])
            port.feed(chunk)
            clock.advance(len(chunk) / 11520.0)  # the bytes' time at 115200 baud
            scans += driver.poll()
        results.append((scans, driver.stats))
    scans, stats = results[0]
    assert stats.crc_failures > 3 and stats.garbage_bytes > 20 and len(scans) >= 3
    for scan in scans:
        ranges = scan.ranges_m[np.isfinite(scan.ranges_m)]
        assert len(scan) > 250 and np.all((ranges >= 0.8) & (ranges < 1.7))  # what was sent, never garbage
        assert np.all(np.isnan(scan.ranges_m[scan.intensities == 0]))  # quality 0: no return
    for other, other_stats in results[1:]:
        assert (other_stats.packets, other_stats.crc_failures, other_stats.garbage_bytes, other_stats.spinup_packets) \
            == (stats.packets, stats.crc_failures, stats.garbage_bytes, stats.spinup_packets)
        assert len(other) == len(scans)
        for a, b in zip(scans, other):
            assert np.array_equal(a.angles_rad, b.angles_rad)
            assert np.array_equal(a.ranges_m, b.ranges_m, equal_nan=True)
