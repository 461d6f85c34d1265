"""The NMEA driver against gpsd: every real capture decoded, compared with gpsd's own reports.

Each ``tests/data/nmea/*.log`` is a byte stream from a real receiver and the
``.log.chk`` beside it is what gpsd reported after each sentence (from the GPSD
regression suite). gpsd reports once per cycle and carries values between
sentences, so the comparison is between SETS: every position the driver gives
must be one gpsd reported for the same time of day (with the same altitude),
and every position gpsd reported from a fix must come out of the driver.

Two gpsd habits are allowed for, explicitly:
- gpsd also reports a position right after a sentence that says "no fix"
  (mtk-3301, GGA quality 0); the driver must not. Such reports are set aside
  as "not from a fix": the ones whose triggering sentence is a GGA with quality
  0, an RMC/GLL with status V.
- gpsd moves dates it finds too old forward by 1024 GPS weeks (its week
  rollover guard): neo-m8n's 2015-03-18 is reported as 2034-11-01.
- gpsd reports a cycle when it ends; a log cut off mid-cycle (neo-m8n) has a
  last cycle gpsd never reported. Records later than gpsd's last report are
  exempt from "gpsd reported it" (at most one cycle's worth).
"""

from __future__ import annotations

import datetime as dt
import io
import json
import math
from decimal import Decimal
from functools import reduce
from pathlib import Path

import pytest

from beastbt.devices.gps_decode import decode_file
from beastbt.devices.nmea_gps import parse_coordinate

DATA = Path(__file__).parent / "data" / "nmea"
CAPTURES = sorted(p.name for p in DATA.glob("*.log"))
DEG_TOL = 1e-6
"""Position agreement required, degrees (the brief: 1e-6)."""
PRINTED_DEG_TOL = 5e-9
"""gpsd prints 9 decimals; exact parsing agrees with that print to rounding (plus float fuzz)."""
ALT_TOL_M = 5e-4
"""gpsd prints altitudes with 4 decimals."""
SPEED_TOL_MPS = 5e-4 + 1e-9
"""gpsd prints speeds with 3 decimals (rounded)."""
TRACK_TOL_DEG = 5e-5 + 1e-9
"""gpsd prints tracks with 4 decimals."""
GPS_ROLLOVER = dt.timedelta(weeks=1024)
GGA_QUALITY_TO_GPSD_STATUS = {1: 1, 2: 2, 4: 3, 5: 4}
"""gpsd's TPV ``status`` for a GGA quality (absent in the JSON means 1)."""


def test_every_capture_is_covered():
    assert len(CAPTURES) == 7
    for name in CAPTURES:
        assert (DATA / (name + ".chk")).exists()
    assert "GPSD project" in (DATA / "README.md").read_text()


# --- reading gpsd's reports and the raw log -----------------------------------------------------

def _nmea_ok(line: str) -> bool:
    """True for a sentence whose checksum is right (a tiny independent check, not the driver's)."""
    if not line.startswith("$") or "*" not in line:
        return False
    body, cs = line[1:].rsplit("*", 1)
    try:
        return reduce(lambda a, c: a ^ ord(c), body, 0) == int(cs[:2], 16)
    except ValueError:
        return False


def _says_fix(line: str) -> bool:
    """Whether a GGA/RMC/GLL sentence claims a valid fix (by its fix field only)."""
    f = line.split("*")[0].split(",")
    kind = f[0][3:]
    if kind == "GGA":
        return f[6] not in ("", "0")
    if kind == "RMC":
        return f[2] == "A" and (len(f) < 13 or f[12] != "N")
    if kind == "GLL":
        return len(f) > 6 and f[6] == "A"
    return False


def _says_no_fix(line: str) -> bool:
    f = line.split("*")[0].split(",")
    return f[0][3:] in ("GGA", "RMC", "GLL") and not _says_fix(line)


def read_chk(name: str):
    """gpsd's TPV reports with position, each tagged with whether it came from a fix,
    and (GGA sentence, SKY report after it) pairs."""
    tpvs, sky_after_gga = [], []
    last_sentence = ""
    for line in (DATA / (name + ".chk")).read_text(encoding="latin-1").splitlines():
        if line.startswith("{"):
            report = json.loads(line)
            if report["class"] == "TPV" and "lat" in report:
                report["from_fix"] = not _says_no_fix(last_sentence)
                tpvs.append(report)
            if report["class"] == "SKY" and last_sentence[3:6] == "GGA" and _says_fix(last_sentence):
                sky_after_gga.append((last_sentence, report))
        elif line.startswith("$"):
            last_sentence = line
    return tpvs, sky_after_gga


def fix_sentences_in_log(name: str) -> list[str]:
    """The sentences of the raw log that claim a fix and have a right checksum."""
    out = []
    for raw in (DATA / name).read_bytes().split(b"\n"):
        line = raw.decode("latin-1").strip()
        if line.startswith("$") and _nmea_ok(line) and _says_fix(line):
            out.append(line)
    return out


def decode(name: str) -> tuple[list[dict], str]:
    out, err = io.StringIO(), io.StringIO()
    assert decode_file(str(DATA / name), out, err) == 0
    records = [json.loads(line) for line in out.getvalue().splitlines()]
    return records, err.getvalue()


def tod(iso: str) -> str:
    return iso.split("T")[1]


def same_date(ours: str, gpsd: str) -> bool:
    a = dt.date.fromisoformat(ours.split("T")[0])
    b = dt.date.fromisoformat(gpsd.split("T")[0])
    return a == b or b - a == GPS_ROLLOVER


def same_position(d: dict, g: dict, tol: float = DEG_TOL) -> bool:
    return abs(d["lat"] - g["lat"]) <= tol and abs(d["lon"] - g["lon"]) <= tol


def consistent(d: dict, g: dict) -> bool:
    """A decoded record and a gpsd report describe the same measurement."""
    if not same_position(d, g):
        return False
    if d["time"] is not None and "time" in g:
        if tod(d["time"]) != tod(g["time"]) or not same_date(d["time"], g["time"]):
            return False
    if d["alt_msl"] is not None and "altMSL" in g and abs(d["alt_msl"] - g["altMSL"]) > ALT_TOL_M:
        return False
    return True


def candidates(d: dict, tpvs: list[dict]) -> list[dict]:
    """gpsd's reports d must be among: those at d's time of day when gpsd has any, else all."""
    if d["time"] is not None:
        at_time = [g for g in tpvs if "time" in g and tod(g["time"]) == tod(d["time"])]
        if at_time:
            return at_time
    return tpvs


# --- the oracle -----------------------------------------------------------------------------------

@pytest.mark.parametrize("name", CAPTURES)
def test_one_record_per_fix_sentence(name):
    """Every sentence that claims a fix gives exactly one record, in order; nothing else does."""
    records, err = decode(name)
    expected = fix_sentences_in_log(name)
    assert [r["sentence"] for r in records] == [s[3:6] for s in expected]
    for r, s in zip(records, expected):
        assert r["quality"] >= 1
        f = s.split("*")[0].split(",")
        lat_field, lon_field = (f[2:6] if s[3:6] == "GGA" else f[3:7] if s[3:6] == "RMC" else f[1:5])[0::2]
        # Independent exact reference: decimal degrees from the text, rounded once.
        ref_lat = float(Decimal(lat_field[:2]) + Decimal(lat_field[2:]) / 60)
        assert abs(abs(r["lat"]) - ref_lat) < 1e-12
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("name", CAPTURES)
def test_positions_match_gpsd_both_ways(name):
    records, _ = decode(name)
    tpvs, _ = read_chk(name)
    from_fix = [g for g in tpvs if g["from_fix"]]
    # Every decoded position is one gpsd reported from a fix at that time, with that altitude.
    last_tod = max((tod(g["time"]) for g in tpvs if "time" in g), default=None)
    unreported = [d for d in records if d["time"] is not None and last_tod is not None and tod(d["time"]) > last_tod]
    assert len(unreported) <= 3, "only a final, unterminated cycle may be missing from gpsd's reports"
    for d in records:
        if d in unreported:
            continue
        pool = candidates(d, from_fix)
        assert any(consistent(d, g) for g in pool), f"{name}: decoded {d} not among gpsd's reports"
        # ... and agrees with gpsd's printed 9 decimals, not just to 1e-6.
        assert any(same_position(d, g, PRINTED_DEG_TOL) for g in pool)
    # Every position gpsd reported from a fix comes out of the driver.
    for g in from_fix:
        assert any(consistent(d, g) for d in records), f"{name}: gpsd's {g} missing from the decoded records"


@pytest.mark.parametrize("name", CAPTURES)
def test_times_and_dates_match_gpsd(name):
    records, _ = decode(name)
    tpvs, _ = read_chk(name)
    gpsd_times = {tod(g["time"]): g["time"] for g in tpvs if "time" in g and g["from_fix"]}
    timed = [d for d in records if d["time"] is not None]
    if name == "bu303-nofix.log":
        assert timed == []
        return
    assert timed, "a capture with RMC or ZDA must give dated fixes"
    matched = 0
    for d in timed:
        assert d["time"].endswith("Z") and len(d["time"]) == len("2015-04-13T20:26:40.000Z")
        if tod(d["time"]) in gpsd_times:
            assert same_date(d["time"], gpsd_times[tod(d["time"])])
            matched += 1
    assert matched >= len(timed) // 2


@pytest.mark.parametrize("name", CAPTURES)
def test_speeds_and_tracks_match_gpsd(name):
    """RMC speed (knots -> m/s) and course agree with gpsd's TPV speed/track of that time."""
    records, _ = decode(name)
    tpvs, _ = read_chk(name)
    rmc = [d for d in records if d["sentence"] == "RMC"]
    compared = 0
    for d in rmc:
        assert d["speed_mps"] is not None
        at_time = [g for g in tpvs if "time" in g and tod(g["time"]) == tod(d["time"])]
        with_track = [g for g in at_time if "track" in g]
        if with_track:
            assert d["track_deg"] is not None
            assert any(abs(g["track"] - d["track_deg"]) <= TRACK_TOL_DEG
                       and abs(g["speed"] - d["speed_mps"]) <= SPEED_TOL_MPS for g in with_track), (name, d)
            compared += 1
        elif any("speed" in g for g in at_time):
            # neo-m8n: empty course field, so no track on either side.
            assert d["track_deg"] is None
            assert any(abs(g["speed"] - d["speed_mps"]) <= SPEED_TOL_MPS for g in at_time if "speed" in g)
            compared += 1
    for g in tpvs:
        if "track" in g:
            assert any(tod(d["time"]) == tod(g["time"]) and abs(g["track"] - d["track_deg"]) <= TRACK_TOL_DEG
                       and abs(g["speed"] - d["speed_mps"]) <= SPEED_TOL_MPS for d in rmc), (name, g)
    if name == "bu303-nofix.log":
        assert compared == 0
    else:
        assert compared >= max(1, len(rmc) // 2)
    for d in records:
        if d["sentence"] != "RMC":
            assert d["speed_mps"] is None and d["track_deg"] is None


@pytest.mark.parametrize("name", CAPTURES)
def test_quality_hdop_sats_match_gpsd(name):
    records, _ = decode(name)
    tpvs, sky_after_gga = read_chk(name)
    gga = [d for d in records if d["sentence"] == "GGA"]
    gga_sentences = [s for s in fix_sentences_in_log(name) if s[3:6] == "GGA"]
    by_sentence = dict(zip(gga_sentences, gga))
    checked = 0
    for sentence, sky in sky_after_gga:
        d = by_sentence[sentence]
        assert d["hdop"] == pytest.approx(sky["hdop"], abs=5e-3)
        assert d["sats"] == sky["uSat"]
        checked += 1
    for d in gga:
        assert d["alt_msl"] is not None
        for g in candidates(d, tpvs):
            if consistent(d, g) and d["quality"] in GGA_QUALITY_TO_GPSD_STATUS:
                assert g.get("status", 1) == GGA_QUALITY_TO_GPSD_STATUS[d["quality"]], (name, d, g)
    if gga:
        assert checked >= 1


def test_no_fix_capture_gives_nothing():
    records, err = decode("bu303-nofix.log")
    assert records == []
    assert "0 positions" in err and "garbage" in err


def test_position_gpsd_reports_from_a_no_fix_sentence_is_not_ours():
    """mtk-3301: gpsd reports 52.216316550, 6.884965100 after a quality-0 GGA; the driver must not."""
    records, _ = decode("mtk-3301.log")
    tpvs, _ = read_chk("mtk-3301.log")
    not_from_fix = [g for g in tpvs if not g["from_fix"]]
    assert [round(g["lat"], 9) for g in not_from_fix] == [52.21631655]
    assert not any(same_position(d, not_from_fix[0], 1e-7) for d in records)
    assert len(records) == 8  # GGA+RMC of 081436..081439, all after the fix came


def test_fuzzy_cases_exact():
    """The values that trip float arithmetic: coordinates and times come out exact."""
    records, _ = decode("nmea-fuzzy-cases.log")
    lines = fix_sentences_in_log("nmea-fuzzy-cases.log")
    for r, s in zip(records, lines):
        f = s.split("*")[0].split(",")
        lat, ns, lon, ew = (f[2:6] if s[3:6] == "GGA" else f[3:7])
        assert r["lat"] == float(Decimal(lat[:2]) + Decimal(lat[2:]) / 60)
        assert r["lon"] == -float(Decimal(lon[:3]) + Decimal(lon[3:]) / 60)
        assert parse_coordinate(lat, ns, is_latitude=True) == r["lat"]
        if r["time"] is not None:
            tod_field = f[1]
            assert tod(r["time"]) == f"{tod_field[0:2]}:{tod_field[2:4]}:{tod_field[4:6]}.{(tod_field[7:] + '000')[:3]}Z"
        if r["sentence"] == "RMC":
            assert r["speed_mps"] == pytest.approx(float(f[7]) * 1852 / 3600, rel=1e-12)
            assert math.isclose(r["track_deg"], float(f[8]))
    times = [r["time"] for r in records if r["time"]]
    assert "2020-03-18T13:28:20.600Z" in times and "2020-03-18T13:28:29.900Z" in times


def epochs_with_gga_fix(name: str) -> set[str]:
    """Times of day (hh:mm:ss.sss, as in the records) of the epochs whose GGA claims a fix."""
    out = set()
    for s in fix_sentences_in_log(name):
        if s[3:6] == "GGA":
            t = s.split(",")[1]
            out.add(f"{t[0:2]}:{t[2:4]}:{t[4:6]}.{(t[7:] + '000')[:3]}Z")
    return out


@pytest.mark.parametrize("name", CAPTURES)
def test_an_epoch_without_its_gga_has_no_sats_or_hdop_as_in_gpsd(name):
    """An RMC whose epoch had no GGA carries sats and HDOP unknown, never another epoch's (gpsd: no DOP error)."""
    records, _ = decode(name)
    tpvs, _ = read_chk(name)
    with_gga = epochs_with_gga_fix(name)
    alone = [d for d in records if d["sentence"] == "RMC" and d["time"] is not None and tod(d["time"]) not in with_gga]
    for d in alone:
        assert d["sats"] is None and d["hdop"] is None and d["alt_msl"] is None, (name, d)
        for g in candidates(d, tpvs):
            if consistent(d, g):
                # gpsd has no HDOP for it either: no error estimate, and a 2D fix (no altitude).
                assert "eph" not in g and "epx" not in g and g["mode"] == 2, (name, g)
    if name == "mtk-3329.log":  # the log starts with the RMC of an epoch whose GGA came before it
        assert [d["time"] for d in alone] == ["2011-02-21T10:21:27.000Z"]
    # An RMC after its epoch's GGA (MTK's order) has the GGA's; one before it (u-blox: RMC first) has none yet.
    gga_seen: set[str] = set()
    after_gga = []
    for s in fix_sentences_in_log(name):
        if s[3:6] == "GGA":
            gga_seen.add(s.split(",")[1])
        elif s[3:6] == "RMC":
            after_gga.append(s.split(",")[1] in gga_seen)
    rmc = [d for d in records if d["sentence"] == "RMC"]
    for d, after in zip(rmc, after_gga, strict=True):
        assert (d["hdop"] is not None and d["sats"] is not None) == after, (name, d)


def test_a_lost_gga_mid_capture_leaves_its_epoch_without_sats_and_hdop(tmp_path):
    """mt3339 with one GGA taken out: that epoch's RMC says sats and HDOP unknown, not the previous epoch's."""
    lines = (DATA / "mt3339.log").read_bytes().split(b"\n")
    ggas = [i for i, raw in enumerate(lines) if raw.startswith(b"$GPGGA") and _says_fix(raw.decode().strip())]
    cut = ggas[len(ggas) // 2]
    lost_tod = lines[cut].decode().split(",")[1]
    cut_log = tmp_path / "cut.log"
    cut_log.write_bytes(b"\n".join(lines[:cut] + lines[cut + 1:]))
    out, err = io.StringIO(), io.StringIO()
    assert decode_file(str(cut_log), out, err) == 0
    records = [json.loads(line) for line in out.getvalue().splitlines()]
    lost = f"{lost_tod[0:2]}:{lost_tod[2:4]}:{lost_tod[4:6]}.{(lost_tod[7:] + '000')[:3]}Z"
    (rmc,) = [d for d in records if d["sentence"] == "RMC" and tod(d["time"]) == lost]
    before = [d for d in records if d["sentence"] == "GGA" and d["time"] is not None and tod(d["time"]) < lost]
    assert before and before[-1]["sats"] is not None  # an earlier epoch had them: they are not carried over
    assert rmc["sats"] is None and rmc["hdop"] is None and rmc["alt_msl"] is None
    # The next epoch has its GGA again, and its values.
    after = [d for d in records if d["sentence"] == "GGA" and d["time"] is not None and tod(d["time"]) > lost]
    assert after and after[0]["sats"] is not None and after[0]["hdop"] is not None
