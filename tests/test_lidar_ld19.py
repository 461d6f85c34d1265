"""The LD19 / D500 driver against a fake LD19 on a pseudo-terminal streaming a known synthetic room."""

from __future__ import annotations

import math
import random
import time

import numpy as np
import serial

from beastbt.core.clock import SimClock, WallClock
from beastbt.devices.ld19 import CRC_TABLE, Ld19Lidar, crc8
from beastbt.devices.lidar_scan import LidarConfig
from fake_ld19 import FakeLd19, crc8_bitwise, ld19_packet
from lidar_support import MemorySerial, poll_until, range_errors

# Entries of LDRobot's CrcTable (ldlidar_stl_ros2, ldlidar_driver/src/dataprocess/lipkg.cpp): first row and last ones.
VENDOR_TABLE_HEAD = [0x00, 0x4D, 0x9A, 0xD7, 0x79, 0x34, 0xE3, 0xAE, 0xF2, 0xBF, 0x68, 0x25]
VENDOR_TABLE_TAIL = [0x06, 0x4B, 0x9C, 0xD1, 0x7F, 0x32, 0xE5, 0xA8]


def open_driver(fake: FakeLd19, events: list | None = None, **config) -> tuple[Ld19Lidar, serial.Serial]:
    port = serial.Serial(fake.port, 230400, timeout=0)
    sink = (lambda kind, text: events.append((kind, text))) if events is not None else (lambda kind, text: None)
    driver = Ld19Lidar(port, WallClock(), sink, config=LidarConfig.from_dict({"type": "ld19", **config}))
    return driver, port


def test_the_crc_table_is_ldrobots():
    assert list(CRC_TABLE[:12]) == VENDOR_TABLE_HEAD
    assert list(CRC_TABLE[-8:]) == VENDOR_TABLE_TAIL
    rng = random.Random(1)
    for _ in range(50):
        data = bytes(rng.randrange(256) for _ in range(46))
        assert crc8(data) == crc8_bitwise(data)


def test_scans_from_the_pty_match_the_room():
    with FakeLd19(rate_hz=10.0) as fake:
        driver, port = open_driver(fake)
        scans = poll_until(driver, lambda s: len(s) >= 3)
        port.close()
    assert len(scans) >= 3
    for scan in scans:
        assert 420 <= len(scan) <= 480  # 4500 points/s at 10 Hz
        errors = range_errors(scan, fake.truth_m)
        assert len(errors) > 400
        # Millimetre quantisation; a few points on the pillar's edges differ by the 0.01 degree angle rounding.
        assert np.mean(errors < 0.003) > 0.98, np.sort(errors)[-10:]
        gaps = np.diff(np.sort(np.degrees(scan.angles_rad)))
        assert gaps.max() < 1.5 and np.ptp(np.degrees(scan.angles_rad)) > 355
        assert abs(scan.scan_rate_hz - 10.0) < 0.05
    assert driver.stats.crc_failures == 0
    assert driver.stats.points_per_scan == len(scans[-1])


def test_the_scan_rate_is_the_heads():
    with FakeLd19(rate_hz=6.0) as fake:
        driver, port = open_driver(fake)
        scans = poll_until(driver, lambda s: len(s) >= 2)
        port.close()
    assert scans and abs(scans[-1].scan_rate_hz - 6.0) < 0.05
    assert 700 <= len(scans[-1]) <= 800  # 4500 / 6
    gap = scans[-1].stamp_s - scans[-2].stamp_s
    assert 0.1 < gap < 0.25  # one revolution of 1/6 s, read in 10 ms polls


def test_garbage_is_skipped_and_decoding_resumes():
    rng = random.Random(7)
    with FakeLd19() as fake:
        driver, port = open_driver(fake)
        poll_until(driver, lambda s: len(s) >= 1)
        for _ in range(5):
            # Random bytes, and things that look like the start of a packet.
            fake.inject(bytes(rng.randrange(256) for _ in range(100)) + b"\x54\x2c\x10\x0e" + b"\x54")
            time.sleep(0.02)
        scans = poll_until(driver, lambda s: len(s) >= 3)
        port.close()
    assert len(scans) >= 3
    assert driver.stats.garbage_bytes >= 500
    for scan in scans:
        assert np.mean(range_errors(scan, fake.truth_m) < 0.003) > 0.98


def test_bad_crc_packets_are_counted_and_dropped():
    events: list = []
    with FakeLd19() as fake:
        driver, port = open_driver(fake, events)
        poll_until(driver, lambda s: len(s) >= 1)
        fake.bad_crc_next = 6
        scans = poll_until(driver, lambda s: len(s) >= 3)
        port.close()
    assert fake.bad_crc_sent == 6
    assert driver.stats.crc_failures >= 6
    for scan in scans:
        # The corrupted packets said 7.777 m everywhere: none of it got through.
        assert not np.any(np.abs(scan.ranges_m - 7.777) < 0.0005)
    assert [kind for kind, _ in events].count("lidar_crc") == 1  # reported once, then counted


def test_half_packets_across_reads_are_joined():
    with FakeLd19() as fake:
        driver, port = open_driver(fake)
        poll_until(driver, lambda s: len(s) >= 1)
        fake.split_next = 8
        scans = poll_until(driver, lambda s: len(s) >= 3, every_s=0.002)
        port.close()
    assert fake.split_next == 0
    assert driver.stats.crc_failures == 0
    assert all(np.mean(range_errors(s, fake.truth_m) < 0.003) > 0.98 for s in scans)


def test_every_split_point_of_a_packet_decodes_the_same():
    # Deterministic: three revolutions fed one byte per poll through an in-memory port.
    packets = []
    stamp = 0
    for rev in range(3):
        for k in range(30):
            start = k * 1200
            packets.append(ld19_packet(3600, start, [(1000 + k, 200)] * 12, start + 1100, stamp))
            stamp += 3
    wire = b"".join(packets)
    port = MemorySerial()
    driver = Ld19Lidar(port, SimClock(), config=LidarConfig.from_dict({"type": "ld19"}))
    scans = []
    for byte in wire:
        port.feed(bytes([byte]))
        scans += driver.poll()
    scans += driver.poll()
    assert driver.stats.packets == 90 and driver.stats.crc_failures == 0 and driver.stats.garbage_bytes == 0
    # The driver cannot know that the first revolution began at 0 (it may have started mid-turn), so it drops it;
    # the third is still open (its end is the next one's first point): one scan of 30 x 12 points.
    assert len(scans) == 1
    assert len(scans[0]) == 360
    assert np.allclose(np.sort(scans[0].ranges_m)[:12], 1.000)


def test_a_head_that_has_not_spun_up_gives_no_scans_until_it_has():
    events: list = []
    with FakeLd19(rate_hz=2.0) as fake:
        driver, port = open_driver(fake, events)
        early = poll_until(driver, lambda s: False, timeout_s=0.8)
        assert early == []
        assert driver.spinning_up and driver.stats.spinup_packets > 0
        fake.rate_hz = 10.0
        scans = poll_until(driver, lambda s: len(s) >= 2)
        port.close()
    assert len(scans) >= 2 and not driver.spinning_up
    assert abs(scans[-1].scan_rate_hz - 10.0) < 0.05
    kinds = [kind for kind, _ in events]
    assert "lidar_spinning_up" in kinds


def test_a_silent_device_goes_stale_and_comes_back():
    events: list = []
    with FakeLd19() as fake:
        driver, port = open_driver(fake, events, stale_after_s=0.3)
        poll_until(driver, lambda s: len(s) >= 1)
        assert not driver.is_stale(driver._clock.now())
        fake.silent = True
        poll_until(driver, lambda s: False, timeout_s=0.6)
        assert driver.is_stale(driver._clock.now())
        assert driver.silent_for_s(driver._clock.now()) > 0.3
        fake.silent = False
        scans = poll_until(driver, lambda s: len(s) >= 1)
        port.close()
    assert scans and not driver.is_stale(driver._clock.now())
    kinds = [kind for kind, _ in events]
    assert kinds.count("lidar_silent") == 1 and kinds.index("lidar_silent") < kinds.index("lidar_back")


def test_range_limits_and_ignored_sectors_are_masked():
    with FakeLd19() as fake:
        driver, port = open_driver(fake, range_m=[0.05, 2.2], ignore_deg=[[80, 100], [170, -170]])
        scans = poll_until(driver, lambda s: len(s) >= 1)
        port.close()
    scan = scans[0]
    deg = np.degrees(scan.angles_rad)
    true = np.array([fake.truth_m(a) for a in scan.angles_rad])
    masked = ((deg > 80.5) & (deg < 99.5)) | (np.abs(deg) > 170.5)
    assert np.all(np.isnan(scan.ranges_m[masked]))
    assert np.all(np.isnan(scan.ranges_m[true > 2.21]))
    near = ((deg > 79.5) & (deg < 100.5)) | (np.abs(deg) > 169.5)  # the sectors and their edges
    kept = ~near & (true < 2.19) & np.isfinite(true)
    assert kept.sum() > 100 and np.all(np.isfinite(scan.ranges_m[kept]))
    assert math.isclose(np.nanmax(scan.ranges_m), 2.2, abs_tol=0.01)


def test_a_packet_across_zero_spreads_its_points_through_360():
    from beastbt.devices.ld19 import packet_angles_deg
    angles = packet_angles_deg(35890, 100)  # 358.9 to 1.0 degrees: 2.1 degrees in 11 steps
    assert angles[0] == 358.9 and abs(angles[-1] - 1.0) < 1e-9
    steps = np.diff(np.unwrap(np.radians(angles)))
    assert np.allclose(np.degrees(steps), 2.1 / 11)
    assert all(0.0 <= a < 360.0 for a in angles)


def _faulty_stream(seed: int) -> tuple[bytes, int, int]:
    """LD19 bytes with what a real line brings: garbage, bad CRCs, cut packets, header bytes inside packets
    (a distance of 0x2C54 mm), a stretch spinning up; how many packets in it are good, and how many of those
    came while it spun up."""
    rng = random.Random(seed)
    out = bytearray()
    angle, good, slow = 0.0, 0, 0
    for i in range(400):
        speed = 1000 if 150 <= i < 170 else 3600  # 20 packets spinning up (2.8 Hz)
        step = speed / 4500.0
        points = [(0x2C54 if k == 3 and i % 7 == 0 else 1000 + (i * 12 + k) % 3000, 200) for k in range(12)]
        packet = ld19_packet(speed, int(round(angle * 100)) % 36000, points,
                             int(round((angle + 11 * step) * 100)) % 36000, i * 3, good_crc=rng.random() > 0.03)
        if rng.random() < 0.02:
            packet = packet[:rng.randrange(2, 46)]  # cut short: the rest never comes
        else:
            ok = crc8(packet[:-1]) == packet[-1]
            good += ok
            slow += ok and speed < 3600
        out += packet
        if rng.random() < 0.05:
            out += bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40))) + b"\x54\x2c\x54"
        angle = (angle + 12 * step) % 360.0
    return bytes(out), good, slow


def test_how_the_bytes_are_cut_into_reads_does_not_change_the_scans():
    # The driver decodes each read at once (all its packets together): one read, reads of any size and
    # single bytes must give the same scans and the same counts.
    wire, good, slow = _faulty_stream(3)
    results = []
    rng = random.Random(5)
    for sizes in ([len(wire)], [1], [47], [230], [rng.randrange(1, 600) for _ in range(len(wire))]):
        port = MemorySerial()
        events: list = []
        driver = Ld19Lidar(port, SimClock(), lambda kind, text: events.append(kind),
                           config=LidarConfig.from_dict({"type": "ld19"}))
        scans, at, k = [], 0, 0
        while at < len(wire):
            size = sizes[k % len(sizes)]
            port.feed(wire[at:at + size])
            at, k = at + size, k + 1
            scans += driver.poll()
        results.append((scans, driver.stats, sorted(set(events))))
    scans, stats, events = results[0]
    assert stats.packets == good and stats.crc_failures > 5 and stats.spinup_packets == slow > 15
    assert stats.garbage_bytes > 100
    assert events == ["lidar_crc", "lidar_spinning_up"]
    assert len(scans) >= 6
    for scan in scans:
        assert 400 <= len(scan) <= 460
        # The distances put in, never garbage: 1000-3999 mm, or the header-looking 0x2C54 (11.348 m).
        mm = np.round(scan.ranges_m * 1000.0)
        assert np.all(((mm >= 1000) & (mm < 4000)) | (mm == 0x2C54))
    for other_scans, other_stats, other_events in results[1:]:
        assert other_stats.packets == stats.packets and other_stats.crc_failures == stats.crc_failures
        assert other_stats.garbage_bytes == stats.garbage_bytes and other_stats.spinup_packets == slow
        assert other_events == events
        assert len(other_scans) == len(scans)
        for a, b in zip(scans, other_scans):
            assert np.array_equal(a.angles_rad, b.angles_rad)
            assert np.array_equal(a.ranges_m, b.ranges_m, equal_nan=True)
            assert a.scan_rate_hz == b.scan_rate_hz
