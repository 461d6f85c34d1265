"""The emulated MTK3339 and the real driver together: the bytes, the noise, the faults, PMTK.

The emulator's sentences are read by the same NmeaGps the robot runs, through
the SimSerialPort, so what is checked here is what a simulated mission sees.
Noise statistics use fixed seeds; the bounds are those of the model, wide
enough for any seed, narrow enough to catch a wrong model.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pynmea2
import pytest

from beastbt.devices.nmea_gps import GpsConfig, NmeaGps
from beastbt.estimation.geodesy import LocalFrame
from beastbt.core.clock import SimClock
from beastbt.sim.gps_emulator import GpsNoiseModel, SimGps, format_coordinate
from beastbt.sim.truth import RobotTruth

ROOT = Path(__file__).parent.parent
FRAME = LocalFrame(44.0688, -121.3142, 1127.0)
TICK_S = 0.05


class Events:
    def __init__(self) -> None:
        self.items: list[tuple[float, str, str]] = []
        self.clock: SimClock | None = None

    def __call__(self, kind: str, text: str) -> None:
        self.items.append((round(self.clock.now(), 6) if self.clock else 0.0, kind, text))

    def kinds(self) -> list[str]:
        return [k for _, k, _ in self.items]


def run(model: GpsNoiseModel, seconds: float, *, seed: int = 7, motion=None, config: GpsConfig | None = None,
        sim_hook=None):
    """Run emulator + driver in lockstep at 20 Hz; return (sim, gps, events, [(t, fix, truth_xy, reported_enu)])."""
    clock = SimClock()
    sim = SimGps(FRAME, model, np.random.default_rng(seed), start_utc=dt.datetime(2024, 6, 1, 23, 59, 0, tzinfo=dt.timezone.utc))
    events = Events()
    events.clock = clock
    gps = NmeaGps(sim.port, clock, events, config=config)
    if sim_hook:
        sim_hook(sim)
    if config is not None:
        gps.configure()
    truth = RobotTruth()
    out = []
    for _ in range(int(round(seconds / TICK_S))):
        truth.t_s = clock.now()
        if motion:
            motion(truth)
        sim.update(truth)
        for fix in gps.poll():
            # Rounded: the clock is a sum of float ticks (4.99999...).
            out.append((round(clock.now(), 6), fix, (truth.x, truth.y), sim.last_reported_enu))
        clock.advance(TICK_S)
    return sim, gps, events, out


def gga_only(rows):
    return [r for r in rows if r[1].sentence == "GGA"]


def errors(rows) -> np.ndarray:
    e = []
    for _, fix, (x, y), _ in rows:
        east, north, _ = FRAME.to_enu(fix.lat, fix.lon, fix.alt_msl)
        e.append((east - x, north - y))
    return np.array(e)


# --- the bytes ---------------------------------------------------------------------------------

def test_default_output_is_mtk3339_at_1hz_with_valid_checksums():
    clock_s = 0.0
    sim = SimGps(FRAME, GpsNoiseModel(), np.random.default_rng(1))
    truth = RobotTruth()
    while clock_s < 10.0 - 1e-9:
        truth.t_s = clock_s
        sim.update(truth)
        clock_s += TICK_S
    raw = sim.port.read(sim.port.in_waiting).decode("ascii")
    lines = raw.split("\r\n")
    assert lines[-1] == ""
    kinds = [pynmea2.parse(line, check=True).sentence_type for line in lines[:-1]]  # raises on a bad checksum
    assert kinds == ["GGA", "GSA", "RMC"] * 10
    first = pynmea2.parse(lines[0])
    assert first.data[0] == "120000.000" and first.talker == "GP"
    rmc = pynmea2.parse(lines[-2])
    assert rmc.data[0] == "120009.000" and rmc.data[8] == "010624"  # start_utc default 2024-06-01T12:00Z + 9 s


def test_coordinates_encode_like_the_receiver():
    assert format_coordinate(44.068843333, is_latitude=True, decimals=4) == ("4404.1306", "N")
    assert format_coordinate(-121.314191667, is_latitude=False, decimals=4) == ("12118.8515", "W")
    assert format_coordinate(-0.9999999999, is_latitude=True, decimals=4) == ("0100.0000", "S")  # carry


def test_round_trip_within_noise_statistics():
    """Stationary robot, 1 Hz, 40 min: the driver sees exactly what was sent, and the errors
    have the model's size, white part and slow correlation."""
    model = GpsNoiseModel(jump_rate_per_s=0.0)
    sim, gps, events, rows = run(model, 2400.0, seed=11)
    rows = gga_only(rows)
    assert len(rows) == 2400
    # What the driver decodes is exactly what the emulator encoded (to float precision).
    for _, fix, _, reported in rows[:50]:
        e, n, u = FRAME.to_enu(fix.lat, fix.lon, fix.alt_msl)
        assert math.dist((e, n, u), reported) < 1e-6
    err = errors(rows)
    expected_axis = math.hypot(model.white_sigma_m, model.bias_sigma_m)  # 2.5 m
    rms = np.sqrt((err ** 2).mean(axis=0))
    assert np.all(rms > 0.6 * expected_axis) and np.all(rms < 1.5 * expected_axis), rms
    # The white part shows in epoch-to-epoch differences (the bias barely moves in 1 s).
    diff_std = np.diff(err, axis=0).std(axis=0)
    assert np.all(np.abs(diff_std / (math.sqrt(2) * model.white_sigma_m) - 1.0) < 0.12), diff_std
    # The bias makes errors 30 s apart correlated (~0.39 for these numbers), white noise alone would not.
    lag = 30
    corr = [np.corrcoef(err[:-lag, i], err[lag:, i])[0, 1] for i in range(2)]
    assert all(0.1 < c < 0.8 for c in corr), corr
    # HDOP/sats/quality as configured, and the driver's covariance from them.
    fix = rows[-1][1]
    assert (fix.quality, fix.sats, fix.hdop) == (1, 9, 0.9)
    assert fix.covariance_enu[0][0] == pytest.approx((0.9 * 4.0) ** 2)
    assert gps.stats.rejected_total == 0 and not gps.is_stale(rows[-1][0])
    # The date rolls over with the time fields (start 23:59:00 on 2024-06-01).
    assert fix.time_utc == "2024-06-02T00:38:59.000Z"


def test_speed_and_course_from_truth():
    def east_then_north(truth):
        truth.v_mps = 1.5
        truth.yaw = 0.0 if truth.t_s < 30 else math.pi / 2
        truth.x += 0.0  # position does not matter for speed

    model = GpsNoiseModel(jump_rate_per_s=0.0)
    _, _, _, rows = run(model, 60.0, motion=east_then_north)
    rmc = [(t, f) for t, f, _, _ in rows if f.sentence == "RMC"]
    east = [f for t, f in rmc if 2 < t < 29]
    north = [f for t, f in rmc if 32 < t < 59]
    assert all(abs(f.speed_mps - 1.5) < 0.3 for f in east + north)
    assert all(abs(f.track_deg - 90.0) < 10 for f in east)
    assert all(min(f.track_deg, 360 - f.track_deg) < 10 for f in north)


def test_same_seed_same_bytes_other_seed_other_bytes():
    def bytes_for(seed):
        sim = SimGps(FRAME, GpsNoiseModel(jump_rate_per_s=0.05), np.random.default_rng(seed))
        truth = RobotTruth()
        for i in range(400):
            truth.t_s = i * TICK_S
            sim.update(truth)
        return sim.port.read(sim.port.in_waiting)

    assert bytes_for(3) == bytes_for(3)
    assert bytes_for(3) != bytes_for(4)


# --- faults ------------------------------------------------------------------------------------

def test_dropout_windows_give_no_fixes_and_stale_data():
    model = GpsNoiseModel(dropouts_s=[(10.0, 20.0), (30.0, 31.5)])
    sim, gps, events, rows = run(model, 40.0)
    times = [t for t, f, _, _ in gga_only(rows)]
    assert not any(10.0 <= t < 20.0 or 30.0 <= t < 31.5 for t in times)
    assert 9.0 in times and 20.0 in times and 29.0 in times and 32.0 in times
    assert len(times) == 40 - 10 - 2
    lost = [t for t, k, _ in events.items if k == "gps_fix_lost"]
    found = [t for t, k, _ in events.items if k == "gps_fix_acquired"]
    assert lost == [10.0, 30.0] and found == [0.0, 20.0, 32.0]
    assert gps.stats.no_fix > 0 and gps.stats.rejected_total == 0


def test_stale_during_dropout():
    clock = SimClock()
    sim = SimGps(FRAME, GpsNoiseModel(dropouts_s=[(5.0, 15.0)]), np.random.default_rng(0))
    gps = NmeaGps(sim.port, clock)
    truth = RobotTruth()
    stale_at = {}
    for _ in range(int(20 / TICK_S)):
        truth.t_s = clock.now()
        sim.update(truth)
        gps.poll()
        stale_at[round(clock.now(), 2)] = gps.is_stale(clock.now())
        clock.advance(TICK_S)
    assert not stale_at[4.5] and stale_at[5.0] and stale_at[14.95] and not stale_at[15.0]


def test_cold_start_has_no_fix_until_it_is_over():
    model = GpsNoiseModel(cold_start_s=35.0)
    sim, gps, events, rows = run(model, 40.0)
    times = sorted({t for t, _, _, _ in rows})
    assert times[0] == 35.0 and len(times) == 5
    assert gps.stats.no_fix == 35 * 2  # GGA and RMC said "no fix" every second
    assert events.kinds()[0] == "gps_fix_acquired"


def test_injected_jump_shows_up_for_its_duration():
    model = GpsNoiseModel(jump_rate_per_s=0.0, white_sigma_m=0.5, bias_sigma_m=0.5)
    sim, gps, events, rows = run(model, 40.0, sim_hook=lambda s: s.inject_jump(30.0, -20.0, 10.0, 5.0))
    rows = gga_only(rows)
    err = errors(rows)
    t = np.array([r[0] for r in rows])
    inside = (t >= 10.0) & (t < 15.0)
    assert inside.sum() == 5
    assert np.allclose(err[inside].mean(axis=0), (30.0, -20.0), atol=2.0)
    assert np.all(np.abs(err[~inside]) < 3.0)
    # The truth metrics hooks: what was sent vs where the robot was.
    assert sim.last_true_enu == (0.0, 0.0, 0.0)
    assert math.dist(sim.last_reported_enu[:2], err[-1]) < 1e-6


def test_random_multipath_jumps_happen_at_the_configured_rate():
    quiet = GpsNoiseModel(jump_rate_per_s=0.0)
    busy = GpsNoiseModel(jump_rate_per_s=0.02, jump_magnitude_m=40.0, jump_duration_s=5.0)
    _, _, _, q_rows = run(quiet, 1000.0, seed=5)
    _, _, _, b_rows = run(busy, 1000.0, seed=5)
    q = np.hypot(*errors(gga_only(q_rows)).T)
    b = np.hypot(*errors(gga_only(b_rows)).T)
    assert q.max() < 15.0
    # ~20 jumps of ~5 s: about 10 % of epochs 20-60 m off.
    frac = (b > 15.0).mean()
    assert 0.03 < frac < 0.25, frac


# --- PMTK --------------------------------------------------------------------------------------

def test_driver_configures_the_emulator():
    cfg = GpsConfig(rate_hz=5, baud=57600, sentences=["RMC", "GGA"])
    sim, gps, events, rows = run(GpsNoiseModel(), 10.0, config=cfg)
    assert sim.rate_hz == 5.0 and sim.baud == 57600
    assert gps.pending_acks == {} and not any(k.startswith("gps_config") for k in events.kinds())
    gga_times = [t for t, f, _, _ in rows if f.sentence == "GGA"]
    assert len(gga_times) == 50  # 5 Hz for 10 s
    assert sim.every_n == {"RMC": 1, "GGA": 1}  # GSA switched off by PMTK314


def test_emulator_refuses_bad_commands():
    sim = SimGps(FRAME, GpsNoiseModel(), np.random.default_rng(0))
    sim.port.write(b"$PMTK220,50*1B\r\n$PMTK999,1*00\r\n")
    sim.port.write(b"$PMTK220,200*2D\r\n")  # corrupted checksum: ignored, no answer
    answers = sim.port.read(sim.port.in_waiting).decode().split()
    assert answers[0].startswith("$PMTK001,220,2*")  # 20 Hz: valid command, cannot do it
    assert sim.rate_hz == 1.0
    assert len(answers) == 1 or answers[1].startswith("$PMTK001,999,")


def test_emulator_unknown_command_and_silent_firmware():
    sim = SimGps(FRAME, GpsNoiseModel(), np.random.default_rng(0))
    from beastbt.devices.nmea_gps import pmtk_sentence
    sim.port.write((pmtk_sentence("605") + "\r\n").encode())
    assert sim.port.read(100).decode().startswith("$PMTK001,605,1*")
    clock, events = SimClock(), Events()
    events.clock = clock
    sim.answer_pmtk = False
    gps = NmeaGps(sim.port, clock, events, config=GpsConfig(rate_hz=2, ack_timeout_s=1.0))
    gps.configure()
    truth = RobotTruth()
    for _ in range(40):
        truth.t_s = clock.now()
        sim.update(truth)
        gps.poll()
        clock.advance(TICK_S)
    assert sim.rate_hz == 2.0  # it obeyed, it just did not say so
    assert [k for k in events.kinds() if k.startswith("gps_config")] == ["gps_config_unacked"]


def test_port_unplug_and_replug_with_the_emulator():
    clock, events = SimClock(), Events()
    events.clock = clock
    sim = SimGps(FRAME, GpsNoiseModel(), np.random.default_rng(0))

    def reopen():
        sim.port.open()
        return sim.port

    gps = NmeaGps(sim.port, clock, events, open_port=reopen, config=GpsConfig(reopen_interval_s=1.0))
    truth = RobotTruth()
    got = []
    for _ in range(int(12 / TICK_S)):
        truth.t_s = clock.now()
        if abs(truth.t_s - 3.0) < 1e-9:
            sim.port.unplug()
        if abs(truth.t_s - 7.0) < 1e-9:
            sim.port.replug()
        sim.update(truth)
        got += [(clock.now(), f) for f in gps.poll()]
        clock.advance(TICK_S)
    times = sorted({round(t, 2) for t, _ in got})
    assert times[:3] == [0.0, 1.0, 2.0] and 3.0 not in times and 6.0 not in times and 8.0 in times
    kinds = events.kinds()
    assert kinds.count("gps_port_lost") == 1 and kinds.count("gps_port_reopened") == 1


# --- the model's configuration -------------------------------------------------------------------

def test_model_from_dict_and_schema():
    model = GpsNoiseModel.from_dict({"rate_hz": 5, "dropouts_s": [[10, 20]], "cold_start_s": 35})
    assert model.dropouts_s == [(10.0, 20.0)] and model.rate_hz == 5
    with pytest.raises(ValueError, match="unknown gps sim key.*white_sigma"):
        GpsNoiseModel.from_dict({"white_sigma": 1.0})
    for bad in ({"rate_hz": 20}, {"dropouts_s": [[5, 1]]}, {"sentences": ["GSV"]}, {"bias_tau_s": 0},
                {"dropouts_s": [[1, 2, 3]]}, {"sats": 2.5}):
        with pytest.raises(ValueError):
            GpsNoiseModel.from_dict(bad)
    schema = json.loads((ROOT / "schemas" / "parts" / "gps_sim.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    v = jsonschema.Draft202012Validator(schema)
    v.validate({"rate_hz": 5, "dropouts_s": [[10, 20]], "cold_start_s": 35})
    assert not v.is_valid({"white_sigma": 1.0})
    assert set(schema["properties"]) == set(GpsNoiseModel.__dataclass_fields__)
    default = GpsNoiseModel()
    for name, prop in schema["properties"].items():
        assert prop["default"] == getattr(default, name), name
        assert prop["description"]
