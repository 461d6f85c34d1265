"""The simulated LiDARs: their bytes, decoded by the real LD19 and RPLIDAR A1 drivers, against hand geometry.

The emulators (beastbt/sim/lidar_emulator.py) ray-cast the world and write
the model's wire protocol; the scans checked here are what the drivers
(beastbt/devices/ld19.py, rplidar.py) make of those bytes. The expected
ranges are computed here by hand (a ray against the corridor's rectangle,
against a circle), not with the emulator's caster.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from beastbt.blackboard.types import LaserScan
from beastbt.core.clock import SimClock
from beastbt.core.events import EventLog
from beastbt.devices.lidar_scan import LidarConfig, LidarMounting, base_points_xy
from beastbt.parts.lidar import lidar_driver
from beastbt.robot.profile import load_profile
from beastbt.sim.dynamics import Wall
from beastbt.sim.lidar_emulator import A1_MODEL, LD19_MODEL, RayCaster, SimRplidarA1, make_emulator
from beastbt.sim.obstacles import CylinderObstacle
from beastbt.sim.robot import build_simulator
from beastbt.sim.truth import RobotTruth
from beastbt.sim.world import load_world
from beastbt.testing import MissionHarness
from conftest import REPO
from recording_support import PATROL, record_run

CORRIDOR = [Wall(0.0, -1.0, 10.0, -1.0), Wall(0.0, 1.0, 10.0, 1.0), Wall(0.0, -1.0, 0.0, 1.0),
            Wall(10.0, -1.0, 10.0, 1.0)]
"""worlds/corridor.yaml: 10 m x 2 m."""
MODELS = {"ld19": LD19_MODEL, "rplidar_a1": A1_MODEL}
OFFICIAL_LASER_SCAN = Path("/work/shared/data/foxglove/LaserScan.json")
LASER_SCAN_SCHEMA = OFFICIAL_LASER_SCAN if OFFICIAL_LASER_SCAN.exists() else REPO / "tests/data/foxglove/LaserScan.json"


def rectangle_range(x: float, y: float, angle: float, x0=0.0, x1=10.0, y0=-1.0, y1=1.0) -> float:
    """Distance from (x, y) inside the rectangle to its side along ``angle`` (rad, world), by hand."""
    c, s = math.cos(angle), math.sin(angle)
    hits = []
    if c > 1e-12:
        hits.append((x1 - x) / c)
    if c < -1e-12:
        hits.append((x0 - x) / c)
    if s > 1e-12:
        hits.append((y1 - y) / s)
    if s < -1e-12:
        hits.append((y0 - y) / s)
    return min(hits)


def circle_range(x: float, y: float, angle: float, cx: float, cy: float, r: float) -> float:
    """Distance from (x, y) outside a circle to it along ``angle`` (inf when the ray misses), by hand."""
    c, s = math.cos(angle), math.sin(angle)
    along = (cx - x) * c + (cy - y) * s
    off2 = (cx - x) ** 2 + (cy - y) ** 2 - along * along
    if along <= 0 or off2 > r * r:
        return math.inf
    return along - math.sqrt(r * r - off2)


def sigma(model, r):
    return model.range_sigma_m + model.range_sigma_ratio * r


class Rig:
    """An emulator and the real driver on its port, stepped together on a simulated clock at 100 Hz."""

    def __init__(self, kind: str, walls=(), obstacles=(), truth=None, mounting=(0.0, 0.0, 0.0), seed: int = 1,
                 contact=None) -> None:
        self.truth = truth if truth is not None else RobotTruth(x=1.0, y=0.0, yaw=0.0)
        self.device = make_emulator(kind, RayCaster(list(walls), list(obstacles)), self.truth, contact, mounting,
                                    np.random.default_rng(seed))
        self.clock = SimClock()
        self.events = EventLog(self.clock)
        self.driver = lidar_driver(LidarConfig(type=kind, port="sim"), self.device.port, self.clock, self.events)
        self.t = 0.0
        self.scans: list[LaserScan] = []

    def run(self, seconds: float, before_step=None) -> list[LaserScan]:
        for _ in range(int(round(seconds / 0.01))):
            self.t = round(self.t + 0.01, 9)
            if before_step is not None:
                before_step(self.t)
            self.clock.set(self.t)
            self.device.update(self.t, 0.01)
            self.scans += self.driver.poll()
        return self.scans


def lidar_pose(truth, mounting):
    c, s = math.cos(truth.yaw), math.sin(truth.yaw)
    mx, my, myaw = mounting
    return truth.x + c * mx - s * my, truth.y + s * mx + c * my, truth.yaw + math.radians(myaw)


@pytest.mark.parametrize("kind", ["ld19", "rplidar_a1"])
@pytest.mark.parametrize("pose, mounting", [((1.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
                                            ((4.0, 0.3, 30.0), (0.1, 0.05, 90.0))])
def test_ranges_in_the_corridor_match_the_geometry(kind, pose, mounting):
    truth = RobotTruth(x=pose[0], y=pose[1], yaw=math.radians(pose[2]))
    rig = Rig(kind, CORRIDOR, truth=truth, mounting=mounting)
    scans = rig.run(2.5)
    model = MODELS[kind]
    assert len(scans) >= 5
    ox, oy, oyaw = lidar_pose(truth, mounting)
    errors, normalised = [], []
    for scan in scans:
        assert abs(len(scan) - model.points_per_s / model.rate_hz) <= 3
        expected = np.array([rectangle_range(ox, oy, oyaw + a) for a in scan.angles_rad])
        ok = np.isfinite(scan.ranges_m)
        errors.append(scan.ranges_m[ok] - expected[ok])
        normalised.append((scan.ranges_m[ok] - expected[ok]) / sigma(model, expected[ok]))
    err, z = np.concatenate(errors), np.concatenate(normalised)
    assert abs(np.median(err)) < 0.01  # unbiased
    assert np.mean(np.abs(z) < 4.5) > 0.999  # every point where the wall is, within its noise (+ mm rounding)
    # At known angles: straight ahead of the LiDAR, to its left, behind, to its right.
    scan = scans[-1]
    for bearing in (0.0, math.pi / 2, math.pi, -math.pi / 2):
        i = int(np.argmin(np.abs(np.angle(np.exp(1j * (scan.angles_rad - bearing))))))
        want = rectangle_range(ox, oy, oyaw + scan.angles_rad[i])
        if np.isfinite(scan.ranges_m[i]):
            assert scan.ranges_m[i] == pytest.approx(want, abs=5 * sigma(model, want) + 0.002)


def test_base_points_put_the_returns_where_the_walls_are_around_the_robot():
    truth = RobotTruth(x=4.0, y=0.3, yaw=math.radians(30.0))
    mounting = LidarMounting(x_m=0.1, y_m=0.05, z_m=0.1, yaw_deg=90.0)
    scan = Rig("ld19", CORRIDOR, truth=truth, mounting=(0.1, 0.05, 90.0)).run(0.5)[-1]
    xy = base_points_xy(scan, mounting)
    c, s = math.cos(truth.yaw), math.sin(truth.yaw)
    wx, wy = truth.x + c * xy[:, 0] - s * xy[:, 1], truth.y + s * xy[:, 0] + c * xy[:, 1]  # base_link -> world
    to_wall = np.minimum.reduce([np.abs(wy - 1.0), np.abs(wy + 1.0), np.abs(wx), np.abs(wx - 10.0)])
    assert len(xy) == scan.valid_count and np.percentile(to_wall, 99) < 0.08


@pytest.mark.parametrize("kind", ["ld19", "rplidar_a1"])
def test_a_cylinder_in_the_open_is_seen_at_its_bearing_and_nothing_else_returns(kind):
    post = CylinderObstacle(3.0, 1.0, 0.2)
    truth = RobotTruth(x=0.0, y=0.0, yaw=0.0)
    scans = Rig(kind, obstacles=[post], truth=truth).run(2.0)
    model = MODELS[kind]
    for scan in scans:
        expected = np.array([circle_range(0.0, 0.0, a, 3.0, 1.0, 0.2) for a in scan.angles_rad])
        hit = np.isfinite(scan.ranges_m)
        assert not np.any(hit & ~np.isfinite(expected))  # nothing where there is nothing
        both = hit & np.isfinite(expected)
        assert both.sum() >= 0.8 * np.isfinite(expected).sum()  # dropouts are rare
        assert np.all(np.abs(scan.ranges_m[both] - expected[both]) < 5 * sigma(model, expected[both]) + 0.002)
    hits = scans[-1].angles_rad[np.isfinite(scans[-1].ranges_m)]
    assert np.mean(hits) == pytest.approx(math.atan2(1.0, 3.0), abs=math.radians(model.step_deg))  # its bearing
    width = 2 * math.asin(0.2 / math.hypot(3.0, 1.0))
    assert len(hits) == pytest.approx(width / math.radians(model.step_deg), abs=2.5)  # and its angular size
    assert np.nanmin(scans[-1].ranges_m) == pytest.approx(math.hypot(3.0, 1.0) - 0.2, abs=0.06)


def test_a_walking_person_is_seen_where_it_is_at_scan_time():
    world = load_world(REPO / "worlds" / "corridor_person.yaml")
    sim = build_simulator(load_profile("sim"), world, seed=1)
    device = make_emulator("ld19", RayCaster(world.walls, world.obstacles), sim.truth, sim.drive.contact,
                           (0.0, 0.0, 0.0), np.random.default_rng(5))
    sim.emulators.append(device.update)
    clock = SimClock()
    driver = lidar_driver(LidarConfig(type="ld19", port="sim"), device.port, clock, EventLog(clock))
    person = world.obstacles[0]
    seen = []
    t = 0.0
    while t < 11.0:
        t = round(t + 0.05, 9)
        sim.advance(t)
        clock.set(t)
        for scan in driver.poll():
            px, py = person.position_at(scan.stamp_s - 0.5 / LD19_MODEL.rate_hz)  # mid-revolution
            bearing = math.atan2(py - sim.truth.y, px - sim.truth.x)
            near = np.abs(np.angle(np.exp(1j * (scan.angles_rad - bearing)))) < math.radians(4)
            seen.append((scan.stamp_s, np.nanmin(scan.ranges_m[near]), math.hypot(px - 1.0, py) - person.radius_m))
    assert sim.truth.x == pytest.approx(1.0) and len(seen) > 90
    walking = [(t, got, want) for t, got, want in seen if t > 6.0]
    assert walking[0][1] > walking[-1][1] + 3.0  # it came closer: about 4 m in 5 s
    for _, got, want in walking:
        assert got == pytest.approx(want, abs=0.12)  # 8 cm walked per revolution, plus the noise
    before = [got for t, got, _ in seen if t < 4.5]
    assert np.median(before) == pytest.approx(math.hypot(9.5 - 1.0, 0.3) - 0.25, abs=0.1)  # standing at the far end


def test_noise_and_dropouts_are_plausible_and_the_same_for_a_seed():
    def ranges(seed):
        rig = Rig("ld19", CORRIDOR, seed=seed)
        return np.concatenate([s.ranges_m for s in rig.run(3.0)])

    a, b, c = ranges(7), ranges(7), ranges(8)
    assert np.array_equal(a, b, equal_nan=True)  # deterministic per seed
    assert not np.array_equal(a, c, equal_nan=True)
    scans = Rig("ld19", CORRIDOR, seed=7).run(3.0)
    expected = np.concatenate([[rectangle_range(1.0, 0.0, x) for x in s.angles_rad] for s in scans])
    got = np.concatenate([s.ranges_m for s in scans])
    dropped = np.mean(~np.isfinite(got))  # every ray in the corridor meets a wall within range
    assert 0.4 * LD19_MODEL.dropout < dropped < 2.5 * LD19_MODEL.dropout
    z = (got - expected)[np.isfinite(got)] / sigma(LD19_MODEL, expected[np.isfinite(got)])
    assert 0.8 < np.std(z) < 1.25 and abs(np.mean(z)) < 0.1


@pytest.mark.parametrize("kind", ["ld19", "rplidar_a1"])
def test_scan_rate_and_points_are_the_models(kind):
    rig = Rig(kind, CORRIDOR)
    scans = rig.run(4.0)
    model = MODELS[kind]
    stamps = np.array([s.stamp_s for s in scans])
    assert np.median(np.diff(stamps)) == pytest.approx(1.0 / model.rate_hz, rel=0.1)
    assert scans[-1].scan_rate_hz == pytest.approx(model.rate_hz, rel=0.03)
    assert rig.driver.stats.crc_failures == 0 and rig.driver.stats.garbage_bytes <= 10
    step = np.abs(np.diff(np.unwrap(scans[-1].angles_rad)))
    assert np.median(step) == pytest.approx(math.radians(model.step_deg), rel=0.05)
    if kind == "ld19":
        assert len(scans) >= 38  # streams from power-up
    else:
        assert 16 <= len(scans) <= 22  # after the start-up sequence and the motor's spin-up


def test_the_a1_answers_only_what_it_is_asked_and_scans_only_between_scan_and_stop():
    truth = RobotTruth(x=1.0, y=0.0, yaw=0.0)
    dev = SimRplidarA1(RayCaster(CORRIDOR, []), truth, None, (0.0, 0.0, 0.0), np.random.default_rng(1))
    port = dev.port

    def step(seconds: float, t0: float) -> float:
        t = t0
        for _ in range(int(round(seconds / 0.01))):
            t = round(t + 0.01, 9)
            dev.update(t, 0.01)
        return t

    t = step(1.0, 0.0)
    assert port.in_waiting == 0  # never talks unasked
    port.write(bytes((0xA5, 0x52)))  # GET_HEALTH
    assert port.read(100) == bytes((0xA5, 0x5A, 3, 0, 0, 0, 0x06, 0, 0, 0))
    port.write(bytes((0xA5, 0x50)))  # GET_INFO
    info = port.read(100)
    assert info[:7] == bytes((0xA5, 0x5A, 20, 0, 0, 0, 0x04)) and len(info) == 27 and info[7] == 0x18
    port.write(bytes((0xA5, 0x20)))  # SCAN, motor off (DTR set): the descriptor, then nothing
    assert port.read(100) == bytes((0xA5, 0x5A, 5, 0, 0, 0x40, 0x81))
    t = step(1.0, t)
    assert port.in_waiting == 0
    port.dtr = False  # the motor spins: samples once at speed
    t = step(0.5, t)
    assert port.in_waiting == 0
    t = step(1.0, t)
    n = port.in_waiting
    assert n % 5 == 0 and n / 5 == pytest.approx((1.5 - 0.8) * A1_MODEL.points_per_s, rel=0.1)
    port.read(n)
    port.dtr = True  # the motor stops: no samples...
    t = step(1.0, t)
    assert port.in_waiting == 0
    port.dtr = False  # ...until it is at speed again, and then no backlog of the time it stood still
    t = step(1.0, t)
    assert port.in_waiting / 5 == pytest.approx((1.0 - 0.8) * A1_MODEL.points_per_s, rel=0.1)
    port.read(port.in_waiting)
    port.write(bytes((0xA5, 0x25)))  # STOP: silence
    t = step(0.5, t)
    assert port.in_waiting == 0
    port.write(bytes((0xA5, 0x40)))  # RESET: deaf while it reboots, then its banner
    port.write(bytes((0xA5, 0x52)))
    t = step(0.3, t)
    assert port.in_waiting == 0
    t = step(0.5, t)
    assert port.read(200).startswith(b"RP LIDAR System.")
    assert dev.requests == [0x52, 0x50, 0x20, 0x25, 0x40, 0x52] and dev.state == "idle"


def test_the_a1_driver_runs_its_sequence_against_the_emulator():
    rig = Rig("rplidar_a1", CORRIDOR)
    scans = rig.run(3.0)
    assert rig.driver.info.model_name == "A1M8" and rig.driver.info.firmware == "1.29"
    assert rig.driver.health.text == "good" and rig.driver.state == "scanning" and rig.driver.dtr_works
    assert scans and rig.device.requests[:1] == [0x25]  # the driver stops it first, as the SDK does
    rig.driver.close()  # STOP and motor off
    before = rig.device.port.written_total
    rig.device.port.open()
    t = rig.t
    for _ in range(50):
        t = round(t + 0.01, 9)
        rig.device.update(t, 0.01)
    assert rig.device.state == "idle" and rig.device.motor_since_s is None and rig.device.port.in_waiting == 0
    assert before > 0


# -- the run: io.sensors['lidar'], the blackboard, /scan and /tf ----------------------------------------------

MISSION = "mission: t\nworld: corridor.yaml\nsteps:\n  - drive: {distance: 1 m, speed: 0.2 m/s}\n"


def test_a_recorded_sim_run_has_the_scan_on_the_blackboard_in_the_lidar_frame(tmp_path):
    h = MissionHarness.from_yaml(MISSION, base_dir=REPO / "worlds", seed=2, record_path=str(tmp_path / "r.mcap"))
    assert "lidar" in h.prepared.run.io.sensors
    h.tick_until(lambda h: h.now_s > 2.0)
    scan = h.blackboard("scan")
    assert isinstance(scan, LaserScan) and h.now_s - scan.stamp_s < 0.15 and scan.model == "ld19"
    truth = h.truth
    expected = np.array([rectangle_range(truth.x, truth.y, truth.yaw + a) for a in scan.angles_rad])
    ok = np.isfinite(scan.ranges_m)
    assert np.median(np.abs(scan.ranges_m[ok] - expected[ok])) < 0.03  # the robot moves within a revolution
    h.run_to_end()
    for closer in h.prepared.closers:
        closer()


def test_scan_is_recorded_as_a_foxglove_laser_scan_with_the_lidar_frame_on_tf(tmp_path):
    folder, summary = record_run(PATROL, tmp_path, seed=1, max_time_s=3.0)
    assert summary["recording"]["dropped"] == 0
    schema = json.loads(LASER_SCAN_SCHEMA.read_text(encoding="utf-8"))
    scans, lidar_tf = [], []
    with open(Path(folder) / "run.mcap", "rb") as f:
        for sch, channel, message in make_reader(f).iter_messages(topics=["/scan", "/tf"]):
            data = json.loads(message.data)
            if channel.topic == "/scan":
                assert sch.name == "foxglove.LaserScan" and json.loads(sch.data) == schema
                jsonschema.validate(data, schema)
                scans.append(data)
            else:
                lidar_tf += [tf for tf in data["transforms"] if tf["child_frame_id"] == "lidar"]
    assert 25 <= len(scans) <= 31  # 10 Hz for 3 s (the first revolution is partial)
    first = scans[-1]
    assert first["frame_id"] == "lidar" and 440 <= len(first["ranges"]) <= 460
    assert len(first["intensities"]) == len(first["ranges"])
    # Clockwise head: the angles run down by one revolution less a step.
    span = first["start_angle"] - first["end_angle"]
    assert span == pytest.approx(2 * math.pi * (1 - 1 / len(first["ranges"])), abs=0.03)
    assert lidar_tf and lidar_tf[0]["parent_frame_id"] == "base_link"
    assert lidar_tf[0]["translation"]["z"] == pytest.approx(0.12)  # robots/sim.yaml's mounting


def test_a_replay_gets_back_the_recorded_scans(tmp_path):
    from beastbt.recording.reader import read_recording
    from beastbt.replay import NOT_REPLAYED, recorded_ticks
    h = MissionHarness.from_yaml(MISSION, base_dir=REPO / "worlds", seed=4, record_path=str(tmp_path / "r.mcap"))
    sent: list[LaserScan] = []
    h.prepared.run.recorders.append(lambda rec: sent.extend(r for r in rec.readings if isinstance(r, LaserScan)))
    h.tick_until(lambda h: h.now_s > 2.0)
    h.prepared.run.finish("success", "enough")
    for closer in h.prepared.closers:
        closer()
    rec = read_recording(tmp_path / "r.mcap", keep_order=True, skip_topics=NOT_REPLAYED)
    back = [(src, r) for tick in recorded_ticks(rec) for src, r in tick.readings if isinstance(r, LaserScan)]
    assert len(back) == len(sent) >= 15 and {src for src, _ in back} == {"lidar"}
    for (_, got), want in zip(back, sent):
        assert got.stamp_s == want.stamp_s and got.model == want.model and got.scan_rate_hz == want.scan_rate_hz
        assert np.array_equal(np.isnan(got.ranges_m), np.isnan(want.ranges_m))
        assert np.nanmax(np.abs(got.ranges_m - want.ranges_m)) < 1e-5
        assert np.max(np.abs(np.angle(np.exp(1j * (got.angles_rad - want.angles_rad))))) < 1e-6
        assert np.array_equal(got.intensities, want.intensities)


def test_the_lidar_has_its_own_random_stream_and_shifts_no_other_emulators_draws():
    world = load_world(REPO / "worlds" / "corridor.yaml")
    a, b, c = (build_simulator(load_profile("sim"), world, seed=s) for s in (9, 9, 10))
    before = a.rng.bit_generator.state
    first = a.stream_rng("lidar").random(5)
    assert a.rng.bit_generator.state == before  # the generator the other emulators draw from did not move
    assert np.array_equal(first, b.stream_rng("lidar").random(5))  # the same for a seed
    assert not np.array_equal(first, c.stream_rng("lidar").random(5))
    assert not np.array_equal(first, b.stream_rng("other").random(5))


def test_the_ld19_port_gives_each_packet_once_its_time_has_come_however_often_it_is_read():
    # The LD19's port is fed when the driver reads (not at every physics step): reading at every step, at
    # 20 Hz or once must give the same bytes, and never a packet before its last point was measured.
    def stream(read_every: int) -> tuple[bytes, list[tuple[float, int]]]:
        truth = RobotTruth(x=2.0, y=0.0, yaw=0.3)
        device = make_emulator("ld19", RayCaster(CORRIDOR, []), truth, None, (0.0, 0.0, 0.0),
                               np.random.default_rng(3))
        out, seen = bytearray(), []
        for step in range(1, 301):  # 3 s at the 100 Hz physics rate
            device.update(step * 0.01, 0.01)
            if step % read_every == 0:
                out += device.port.read(device.port.in_waiting)
                seen.append((step * 0.01, len(out)))
        return bytes(out), seen

    every_step, seen = stream(1)
    assert stream(5)[0] == every_step and stream(300)[0] == every_step
    packet_s = 12 / LD19_MODEL.points_per_s
    for t, n in seen:
        assert n == 47 * int(t / packet_s + 1e-6)  # the packets whose end time has come, all of them


def test_an_unplugged_ld19_port_loses_what_came_while_it_was_out():
    truth = RobotTruth(x=2.0, y=0.0, yaw=0.0)
    device = make_emulator("ld19", RayCaster(CORRIDOR, []), truth, None, (0.0, 0.0, 0.0), np.random.default_rng(3))
    for step in range(1, 11):
        device.update(step * 0.01, 0.01)
    device.port.unplug()  # 0.1 s: 37 packets had come; unread, they go with the port
    for step in range(11, 21):
        device.update(step * 0.01, 0.01)
    device.port.replug()
    device.port.open()
    assert device.port.in_waiting == 0  # nothing of what came while it was out
    for step in range(21, 31):
        device.update(step * 0.01, 0.01)
    got = device.port.read(device.port.in_waiting)
    assert len(got) == 47 * (int(0.3 / (12 / LD19_MODEL.points_per_s) + 1e-6) - 75) and got[:2] == b"\x54\x2c"
