"""The NMEA GPS driver on its own: bad bytes, no-fix periods, a vanishing port, PMTK configuration.

Every test talks to the driver through a SimSerialPort (bytes in, bytes out),
the way it talks to pyserial on the robot.
"""

from __future__ import annotations

import json
import subprocess
import sys
from functools import reduce
from pathlib import Path

import jsonschema
import pytest

from beastbt.devices.nmea_gps import GpsConfig, NmeaGps, parse_coordinate, pmtk_sentence
from beastbt.core.clock import SimClock
from beastbt.sim.serial_port import SimSerialPort

ROOT = Path(__file__).parent.parent
MT3339 = ROOT / "tests" / "data" / "nmea" / "mt3339.log"

GGA = "$GPGGA,202640.000,4404.1306,N,12118.8515,W,2,10,0.98,1127.7,M,-19.6,M,0000,0000*6C"
RMC = "$GPRMC,202640.000,A,4404.1306,N,12118.8515,W,0.03,225.97,130415,,,D*73"


def nmea(body: str) -> str:
    """A sentence with its checksum (XOR of the characters between $ and *)."""
    return f"${body}*{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


class Events:
    """An EventSink that keeps what it is told."""

    def __init__(self) -> None:
        self.items: list[tuple[str, str]] = []

    def __call__(self, kind: str, text: str) -> None:
        self.items.append((kind, text))

    def kinds(self) -> list[str]:
        return [k for k, _ in self.items]

    def count(self, kind: str) -> int:
        return self.kinds().count(kind)


@pytest.fixture
def rig():
    clock = SimClock()
    port = SimSerialPort("gps-test")
    events = Events()
    gps = NmeaGps(port, clock, events)
    return clock, port, events, gps


def send(port: SimSerialPort, *lines: str) -> None:
    port.feed("".join(line + "\r\n" for line in lines).encode("latin-1"))


# --- parsing -------------------------------------------------------------------------------------

def test_gga_and_rmc_give_fixes_with_everything(rig):
    clock, port, events, gps = rig
    clock.advance(3.0)
    send(port, GGA, RMC)
    gga, rmc = gps.poll()
    assert (gga.sentence, rmc.sentence) == ("GGA", "RMC")
    assert gga.stamp_s == rmc.stamp_s == 3.0
    assert gga.lat == pytest.approx(44.068843333, abs=1e-9) and gga.lon == pytest.approx(-121.314191667, abs=1e-9)
    assert (gga.alt_msl, gga.quality, gga.sats, gga.hdop) == (1127.7, 2, 10, 0.98)
    assert gga.time_utc is None  # no date seen yet
    assert rmc.time_utc == "2015-04-13T20:26:40.000Z"
    assert rmc.speed_mps == pytest.approx(0.03 * 1852 / 3600) and rmc.track_deg == 225.97
    # RMC has no quality: it takes the GGA's, and the same epoch's altitude.
    assert (rmc.quality, rmc.alt_msl, rmc.hdop) == (2, 1127.7, 0.98)
    assert gps.latest_fix is rmc and not gps.is_stale(3.0)
    assert gps.stats.used == 2 and gps.stats.fixes == 2


def test_every_talker_and_gll_vtg_gsa(rig):
    clock, port, events, gps = rig
    for talker in ("GP", "GN", "GL", "GA", "BD", "GB"):
        fix = gps.feed_line(nmea(f"{talker}GLL,4404.14066,N,12118.85481,W,171925.00,A,A"), 0.0)
        assert fix is not None and fix.sentence == "GLL" and fix.lat == pytest.approx(44.069011)
    gps.feed_line(nmea("GNRMC,171926.00,A,4404.14063,N,12118.85478,W,0.117,,180315,,,A"), 0.0)
    assert gps.feed_line(nmea("GNVTG,45.5,T,,M,2.000,N,3.704,K,A"), 0.0) is None
    gps.feed_line(nmea("GNGSA,A,3,01,11,31,14,22,32,04,25,03,,,,1.56,0.77,1.27"), 0.0)
    fix = gps.feed_line(nmea("GNGLL,4404.14063,N,12118.85478,W,171926.00,A,A"), 0.0)
    # GLL of the same epoch carries VTG's speed/course and GSA's HDOP.
    assert fix.speed_mps == pytest.approx(2.0 * 1852 / 3600) and fix.track_deg == 45.5
    assert fix.hdop == 0.77 and fix.time_utc == "2015-03-18T17:19:26.000Z"


def test_hdop_from_gsa_when_gga_has_none(rig):
    clock, port, events, gps = rig
    gps.feed_line(nmea("GPGSA,A,3,20,16,09,03,,,,,,,,,1.64,1.25,1.31"), 0.0)
    fix = gps.feed_line(nmea("GPGGA,202640.000,4404.1306,N,12118.8515,W,1,10,,1127.7,M,-19.6,M,,"), 0.0)
    assert fix.hdop == 1.25


def test_exact_coordinates_beat_float_minutes():
    # 41 deg 34.49821229' W: computed in decimal, rounded once.
    assert parse_coordinate("4134.49821229", "N", is_latitude=True) == 41.574970204833335
    assert parse_coordinate("09345.03351845", "W", is_latitude=False) == -93.75055864083333
    for bad, hemi, is_lat in [("4460.0000", "N", True), ("9100.0000", "N", True), ("18100.0", "E", False),
                              ("44a4.13", "N", True), ("4404.13", "E", True), ("nan", "N", True), ("", "N", True)]:
        with pytest.raises(ValueError):
            parse_coordinate(bad, hemi, is_latitude=is_lat)


def test_date_rolls_over_at_midnight(rig):
    clock, port, events, gps = rig
    gps.feed_line(nmea("GPRMC,235959.500,A,4404.1306,N,12118.8515,W,0.0,0.0,311215,,,A"), 0.0)
    fix = gps.feed_line(nmea("GPGGA,000000.500,4404.1306,N,12118.8515,W,1,08,1.0,10.0,M,0.0,M,,"), 0.0)
    assert fix.time_utc == "2016-01-01T00:00:00.500Z"
    gps.feed_line(nmea("GPZDA,120000.00,29,02,2024,,"), 0.0)
    fix = gps.feed_line(nmea("GPGGA,120001.25,4404.1306,N,12118.8515,W,1,08,1.0,10.0,M,0.0,M,,"), 0.0)
    assert fix.time_utc == "2024-02-29T12:00:01.250Z"


# --- no fix --------------------------------------------------------------------------------------

def test_no_fix_sentences_give_no_position_and_make_data_stale(rig):
    clock, port, events, gps = rig
    send(port, GGA)
    assert len(gps.poll()) == 1 and "gps_fix_acquired" in events.kinds()
    clock.advance(1.0)
    # What an MTK3339 sends when it loses the sky (quality 0, status V), even with stale coordinates.
    send(port, nmea("GPGGA,202641.000,4404.1306,N,12118.8515,W,0,00,,,M,,M,,"),
         nmea("GPGSA,A,1,,,,,,,,,,,,,,,"),
         nmea("GPRMC,202641.000,V,4404.1306,N,12118.8515,W,0.00,0.00,130415,,,N"),
         nmea("GPGLL,4404.1306,N,12118.8515,W,202641.000,V,N"))
    assert gps.poll() == []
    assert gps.is_stale(clock.now()), "the receiver said no fix: the old fix must not be trusted"
    assert gps.stats.no_fix == 3 and events.count("gps_fix_lost") == 1
    assert gps.latest_fix is not None and gps.latest_fix.stamp_s == 0.0
    clock.advance(1.0)
    send(port, GGA)
    assert len(gps.poll()) == 1 and not gps.is_stale(clock.now())
    assert events.count("gps_fix_acquired") == 2


def test_stale_after_timeout(rig):
    clock, port, events, gps = rig
    assert gps.is_stale(0.0)  # nothing yet
    send(port, GGA)
    gps.poll()
    assert not gps.is_stale(2.5)
    assert gps.is_stale(2.6)


# --- bad input -----------------------------------------------------------------------------------

def test_bad_lines_are_counted_by_reason_and_never_fatal(rig):
    clock, port, events, gps = rig
    bad_checksum = GGA[:-2] + "00"
    port.feed(b"\x00\xff\xfe\x13binary\xb5b\r\n")  # binary garbage (u-blox UBX bytes)
    send(port,
         bad_checksum,                                    # checksum
         GGA[:40],                                        # cut before the checksum
         "$GPGGA,2026" + RMC,                             # cut short by the next sentence
         GGA[:-1],                                        # checksum cut to one digit
         "$POLYN,TIME,RESTART_OCCURRED",                  # no checksum at all
         nmea("GPXYZ,1,2,3"),                             # a sentence type nobody knows
         nmea("GPGGA,202640.000,44x4.1306,N,12118.8515,W,1,10,0.98,1127.7,M,,M,,"),  # nonsense field
         nmea("GPRMC,202640.000,A,4404.1306,N,12118.8515,W,0.03,225.97,321315,,,A"),  # 32nd of the 13th month
         "$GPG\xe9A,1,2*00",                              # high bytes inside a sentence
         nmea("GPGSV,3,1,12,09,88,089,31,07,60,281,44,23,55,123,33,10,44,274,32"),  # fine, just not used
         GGA)
    fixes = gps.poll()
    # The RMC glued behind the cut GGA and the final GGA still come through.
    assert [f.sentence for f in fixes] == ["RMC", "GGA"]
    assert gps.stats.rejected == {"garbage": 2, "checksum": 1, "truncated": 2, "no_checksum": 2,
                                  "unknown_type": 1, "malformed": 2}
    assert gps.stats.ignored == 1 and gps.stats.used == 2
    assert gps.stats.read == gps.stats.used + gps.stats.ignored + gps.stats.rejected_total
    for reason in ("garbage", "checksum", "truncated", "no_checksum", "unknown_type", "malformed"):
        assert events.count(f"gps_{reason}") == 1


def test_bad_data_events_are_rate_limited(rig):
    clock, port, events, gps = rig
    bad = GGA[:-2] + "00"
    for _ in range(20):
        send(port, *[bad] * 50)  # 50 bad lines per tick
        gps.poll()
        clock.advance(1.0)
    assert gps.stats.rejected["checksum"] == 1000
    # First at once, then at most one every 30 s: 1000 bad lines in 20 s give a single event.
    assert events.count("gps_checksum") == 1
    clock.advance(15.0)
    send(port, bad)
    gps.poll()
    assert events.count("gps_checksum") == 2
    assert "1000 sentence(s) rejected" in events.items[-1][1]


def test_partial_lines_wait_for_the_rest(rig):
    clock, port, events, gps = rig
    data = (GGA + "\r\n").encode()
    port.feed(data[:30])
    assert gps.poll() == []
    port.feed(data[30:])
    assert [f.sentence for f in gps.poll()] == ["GGA"]
    assert gps.stats.rejected_total == 0


def test_endless_binary_without_newline_is_dropped(rig):
    clock, port, events, gps = rig
    for _ in range(10):
        port.feed(bytes(range(11, 255)) * 2)  # no 0x0a inside
        gps.poll()
    assert gps.stats.rejected.get("garbage", 0) >= 1
    send(port, "", GGA)
    assert [f.sentence for f in gps.poll()] == ["GGA"]


def test_real_capture_byte_by_byte(rig):
    """The whole mt3339 capture, in ragged chunks, gives what the line-by-line decoder gives."""
    clock, port, events, gps = rig
    raw = b"".join(line + b"\n" for line in MT3339.read_bytes().split(b"\n") if not line.startswith(b"#"))
    fixes = []
    for i in range(0, len(raw), 37):
        port.feed(raw[i:i + 37])
        fixes += gps.poll()
        clock.advance(0.05)
    assert len(fixes) == 60 and gps.stats.rejected_total == 0
    assert {f.quality for f in fixes} == {2}


def test_position_sentences_can_be_limited_to_gga():
    clock, port = SimClock(), SimSerialPort()
    gps = NmeaGps(port, clock, config=GpsConfig(position_sentences=["GGA"]))
    send(port, GGA, RMC)
    assert [f.sentence for f in gps.poll()] == ["GGA"]


# --- covariance ----------------------------------------------------------------------------------

def test_an_epoch_without_its_gga_carries_nothing_from_an_earlier_one(rig):
    """The live path: what the estimator gets for an RMC whose GGA was lost has unknown sats, HDOP and quality."""
    from beastbt.estimation.gps_epochs import EpochFilter

    clock, port, events, gps = rig
    epochs = EpochFilter()
    gsa = nmea("GPGSA,A,3,20,16,09,03,05,06,07,08,10,11,,,1.60,0.98,1.30")
    send(port, GGA, gsa, RMC)  # 20:26:40: a whole epoch (DGPS, 10 satellites, HDOP 0.98)
    (whole,) = epochs(gps.poll())
    assert (whole.sentence, whole.quality, whole.sats, whole.hdop) == ("RMC", 2, 10, 0.98)
    clock.advance(1.0)
    # 20:26:41: the GGA (and its GSA) lost on the wire; the RMC alone, mode letter A (autonomous GPS).
    send(port, nmea("GPRMC,202641.000,A,4404.1310,N,12118.8510,W,0.03,225.97,130415,,,A"))
    (alone,) = epochs(gps.poll())
    assert alone.time_utc == "2015-04-13T20:26:41.000Z"
    assert (alone.quality, alone.sats, alone.hdop, alone.alt_msl) == (1, None, None, None)
    # The EKF gates and weighs it with the HDOP assumed when unknown (2.0) and GPS's base error, not DGPS's 0.98.
    assert alone.covariance_enu == gps.covariance(1, None)
    assert alone.covariance_enu[0][0] == pytest.approx((2.0 * 4.0) ** 2)
    assert gps.latest_fix is alone
    clock.advance(1.0)
    send(port, nmea("GPGGA,202642.000,4404.1306,N,12118.8515,W,1,07,1.40,1127.7,M,-19.6,M,,"))
    fixes = gps.poll()
    assert (fixes[-1].sats, fixes[-1].hdop) == (7, 1.4)  # the next epoch's own


def test_the_same_epoch_written_with_other_decimals_is_one_epoch(rig):
    clock, port, events, gps = rig
    gps.feed_line(nmea("GPGGA,202640.00,4404.1306,N,12118.8515,W,2,10,0.98,1127.7,M,-19.6,M,,"), 0.0)
    rmc = gps.feed_line(RMC, 0.0)  # 202640.000
    assert (rmc.sats, rmc.hdop, rmc.quality, rmc.alt_msl) == (10, 0.98, 2, 1127.7)


def test_gps_decode_prints_null_sats_and_hdop_for_an_rmc_alone(tmp_path):
    log = tmp_path / "lost_gga.log"
    log.write_text("\n".join([
        "# an MTK epoch, then one whose GGA and GSA were lost",
        GGA, nmea("GPGSA,A,3,20,16,09,03,05,06,07,08,10,11,,,1.60,0.98,1.30"), RMC,
        nmea("GPRMC,202641.000,A,4404.1310,N,12118.8510,W,0.03,225.97,130415,,,D"),
    ]) + "\n")
    out = subprocess.run([sys.executable, "-m", "beastbt", "gps", "decode", str(log)], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    records = [json.loads(line) for line in out.stdout.splitlines()]
    assert [(r["sentence"], r["sats"], r["hdop"]) for r in records] == [
        ("GGA", 10, 0.98), ("RMC", 10, 0.98), ("RMC", None, None)]
    assert records[2]["quality"] == 2  # its own mode letter D


@pytest.mark.parametrize("quality,base", [(1, 4.0), (2, 0.1), (4, 0.02), (5, 4.0), (9, 3.0), (6, 10.0), (3, 10.0)])
def test_covariance_is_hdop_times_base_error(quality, base):
    gps = NmeaGps(SimSerialPort(), SimClock())
    fix = gps.feed_line(nmea(f"GPGGA,120000.00,4404.1306,N,12118.8515,W,{quality},10,1.5,10.0,M,0.0,M,,"), 0.0)
    (ee, en, eu), (ne, nn, nu), (ue, un, uu) = fix.covariance_enu
    sigma = max(1.5 * base, 0.01)
    assert ee == pytest.approx(sigma ** 2) and nn == pytest.approx(sigma ** 2)
    assert uu == pytest.approx((2 * sigma) ** 2) and uu > ee
    assert en == ne == eu == ue == nu == un == 0.0


def test_covariance_never_zero_and_hdop_unknown():
    gps = NmeaGps(SimSerialPort(), SimClock())
    rtk = gps.feed_line(nmea("GPGGA,120000.00,4404.1306,N,12118.8515,W,4,20,0.0,10.0,M,0.0,M,,"), 0.0)
    assert rtk.covariance_enu[0][0] > 0 and rtk.covariance_enu[2][2] > rtk.covariance_enu[0][0]
    gps2 = NmeaGps(SimSerialPort(), SimClock())
    rmc = gps2.feed_line(RMC, 0.0)
    assert rmc.hdop is None and rmc.quality == 2  # mode letter D: DGPS
    assert rmc.covariance_enu[0][0] == pytest.approx((2.0 * 0.1) ** 2)


# --- the port ------------------------------------------------------------------------------------

def test_port_that_vanishes_is_reopened():
    clock = SimClock()
    port = SimSerialPort("ttyGPS")
    events = Events()
    attempts = []

    def reopen():
        attempts.append(clock.now())
        port.open()  # raises serial.SerialException while unplugged
        return port

    gps = NmeaGps(port, clock, events, open_port=reopen, config=GpsConfig(reopen_interval_s=2.0))
    send(port, GGA)
    assert len(gps.poll()) == 1
    port.unplug()
    clock.advance(0.05)
    assert gps.poll() == []  # never raises
    assert events.kinds()[-1] == "gps_port_lost" and not gps.port_open
    assert gps.is_stale(clock.now()) and port.is_open is False
    for _ in range(100):  # 5 s unplugged, polled at 20 Hz
        clock.advance(0.05)
        assert gps.poll() == []
    assert attempts == pytest.approx([2.05, 4.05], abs=0.06), "retried every reopen_interval_s, not every poll"
    assert events.count("gps_port_lost") == 1
    port.replug()
    while len(attempts) < 3:
        clock.advance(0.05)
        gps.poll()
    assert events.kinds()[-1] == "gps_port_reopened" and gps.port_open
    assert gps.is_stale(clock.now()), "stale until a new fix arrives"
    send(port, RMC)
    assert [f.sentence for f in gps.poll()] == ["RMC"] and not gps.is_stale(clock.now())


def test_port_unavailable_at_start():
    clock = SimClock()
    events = Events()
    port = SimSerialPort()
    port.unplug()

    def opener():
        port.open()
        return port

    gps = NmeaGps(None, clock, events, open_port=opener, config=GpsConfig(reopen_interval_s=1.0))
    assert gps.poll() == [] and events.kinds() == ["gps_port_lost"]
    assert gps.is_stale(0.0)
    port.replug()
    clock.advance(1.0)
    gps.poll()
    assert events.kinds() == ["gps_port_lost", "gps_port_reopened"]
    send(port, GGA)
    assert len(gps.poll()) == 1


def test_port_lost_without_a_way_back_stays_quiet():
    clock, port, events = SimClock(), SimSerialPort(), Events()
    gps = NmeaGps(port, clock, events)
    port.unplug()
    for _ in range(10):
        assert gps.poll() == []
        clock.advance(1.0)
    assert events.count("gps_port_lost") == 1 and "no way to reopen" in events.items[0][1]


# --- PMTK configuration ----------------------------------------------------------------------------

def test_pmtk_sentences_match_the_datasheet():
    assert pmtk_sentence("220", "200") == "$PMTK220,200*2C"
    assert pmtk_sentence("220", "100") == "$PMTK220,100*2F"
    assert pmtk_sentence("251", "57600") == "$PMTK251,57600*2C"
    assert pmtk_sentence("251", "115200") == "$PMTK251,115200*1F"
    cfg = GpsConfig(rate_hz=5, baud=57600, sentences=["RMC", "GGA"])
    assert cfg.pmtk_commands() == ["$PMTK251,57600*2C", "$PMTK314,0,1,0,1,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0*28",
                                   "$PMTK220,200*2C"]
    assert GpsConfig().pmtk_commands() == []


class AnsweringDevice:
    """A receiver that answers each PMTK command with a chosen flag (or not at all)."""

    def __init__(self, port: SimSerialPort, flags: dict[str, str]) -> None:
        self.port, self.flags = port, flags
        port.on_write = self.on_write

    def on_write(self, data: bytes) -> None:
        for line in data.decode().splitlines():
            cmd = line[5:8]
            if cmd in self.flags:
                self.port.feed((pmtk_sentence("001", cmd, self.flags[cmd]) + "\r\n").encode())


def test_configure_acks_timeouts_and_refusals():
    clock, port, events = SimClock(), SimSerialPort(), Events()
    AnsweringDevice(port, {"220": "3", "314": "1"})  # says nothing about 251
    gps = NmeaGps(port, clock, events, config=GpsConfig(rate_hz=10, baud=115200, sentences=["GGA", "RMC"],
                                                         ack_timeout_s=1.5))
    gps.configure()
    assert port.written.decode().splitlines() == ["$PMTK251,115200*1F",
                                                  "$PMTK314,0,1,0,1,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0*28",
                                                  "$PMTK220,100*2F"]
    assert set(gps.pending_acks) == {"251", "314", "220"}
    send(port, GGA)
    assert len(gps.poll()) == 1  # the answers sit in the stream with the data
    assert set(gps.pending_acks) == {"251"}
    assert events.count("gps_config_failed") == 1 and "unsupported" in dict(events.items)["gps_config_failed"]
    clock.advance(1.4)
    gps.poll()
    assert events.count("gps_config_unacked") == 0
    clock.advance(0.2)
    gps.poll()
    assert events.count("gps_config_unacked") == 1 and "PMTK251" in dict(events.items)["gps_config_unacked"]
    assert gps.pending_acks == {}


def test_configuration_is_sent_again_after_reopen():
    clock, port, events = SimClock(), SimSerialPort(), Events()
    AnsweringDevice(port, {"220": "3"})

    def opener():
        port.open()
        return port

    gps = NmeaGps(port, clock, events, open_port=opener, config=GpsConfig(rate_hz=5, reopen_interval_s=1.0))
    gps.configure()
    gps.poll()
    assert gps.pending_acks == {}
    port.unplug()
    gps.poll()
    port.replug()
    port.written.clear()
    clock.advance(1.0)
    gps.poll()
    assert port.written.decode().strip() == "$PMTK220,200*2C"
    gps.poll()
    assert gps.pending_acks == {} and events.count("gps_config_unacked") == 0


# --- configuration ---------------------------------------------------------------------------------

def test_config_from_dict_rejects_unknown_and_bad_values():
    cfg = GpsConfig.from_dict({"rate_hz": 5, "base_error_m": {"2": 0.5}, "sentences": ["GGA", "RMC"]})
    assert cfg.rate_hz == 5 and cfg.base_error_m[2] == 0.5 and cfg.base_error_m[1] == 4.0
    with pytest.raises(ValueError, match="unknown gps config key.*rate_hz_typo"):
        GpsConfig.from_dict({"rate_hz_typo": 5})
    for bad in ({"rate_hz": 20}, {"baud": 1234}, {"sentences": ["GGX"]}, {"stale_after_s": 0},
                {"base_error_m": {"x": 1.0}}, {"position_sentences": ["GSA"]}, {"reopen_interval_s": "2"}):
        with pytest.raises(ValueError):
            GpsConfig.from_dict(bad)


def test_schema_matches_the_config():
    schema = json.loads((ROOT / "schemas" / "parts" / "gps_device.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    default = GpsConfig()
    for name, prop in schema["properties"].items():
        value = getattr(default, name)
        if isinstance(value, dict):
            value = {str(k): v for k, v in value.items()}
        assert prop["default"] == value, name
        assert prop["description"]
    good = {"port": "/dev/ttyAMA0", "baud": 57600, "rate_hz": 5, "sentences": ["GGA", "RMC"], "base_error_m": {"1": 3.0}}
    validator.validate(good)
    GpsConfig.from_dict(good)
    assert not validator.is_valid({"rate_hz_typo": 5})
    assert set(schema["properties"]) == set(GpsConfig.__dataclass_fields__)


# --- the decoder behind `beastbt gps decode` -----------------------------------------------------

def test_decode_file_reports_unreadable_files(tmp_path):
    import io

    from beastbt.devices.gps_decode import decode_file

    out, err = io.StringIO(), io.StringIO()
    missing = tmp_path / "nope.log"
    assert decode_file(str(missing), out, err) == 2
    assert str(missing) in err.getvalue() and "cannot read" in err.getvalue() and out.getvalue() == ""
    assert decode_file(str(tmp_path), io.StringIO(), io.StringIO()) == 2  # a directory


def test_decode_file_prints_fixes_and_one_summary_line(tmp_path):
    import io

    from beastbt.devices.gps_decode import decode_file

    log = tmp_path / "x.log"
    log.write_bytes(("# a comment with $GPGGA inside is not data\n" + GGA + "\r\n" + GGA[:-2] + "00\r\n"
                     + RMC + "\r\n").encode())
    out, err = io.StringIO(), io.StringIO()
    assert decode_file(str(log), out, err) == 0
    records = [json.loads(line) for line in out.getvalue().splitlines()]
    assert [r["sentence"] for r in records] == ["GGA", "RMC"]
    assert set(records[0]) == {"sentence", "time", "lat", "lon", "alt_msl", "quality", "sats", "hdop",
                               "speed_mps", "track_deg"}
    assert records[1]["alt_msl"] is None and records[0]["speed_mps"] is None
    lines = err.getvalue().splitlines()
    assert len(lines) == 1 and "read 3 sentences" in lines[0] and "checksum 1" in lines[0]
