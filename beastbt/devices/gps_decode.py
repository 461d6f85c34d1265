"""``beastbt gps decode FILE``: run a recorded NMEA log through the GPS driver and print the fixes.

The log is the raw byte stream a receiver sent, one sentence per line; lines
starting with ``#`` are comments. Every line goes through the same
:class:`~beastbt.devices.nmea_gps.NmeaGps` parsing the robot uses, so this is
also how a capture from the field is checked against what the driver makes of it.
"""

from __future__ import annotations

import json
from typing import Any, Optional, TextIO

from beastbt.blackboard.types import GpsFix
from beastbt.devices.nmea_gps import NmeaGps
from beastbt.core.clock import SimClock


def fix_to_record(fix: GpsFix) -> dict[str, Any]:
    """The JSON object printed for one fix.

    ``time`` ISO 8601 UTC (null while the date is unknown), ``lat``/``lon``
    decimal degrees, ``alt_msl`` metres (GGA only), ``speed_mps`` and
    ``track_deg`` (degrees clockwise from true north; RMC only). ``sats``
    and ``hdop`` are those of the fix's own epoch: null for an RMC whose
    epoch had no GGA (or none yet), never an earlier epoch's.
    """
    return {
        "sentence": fix.sentence,
        "time": fix.time_utc,
        "lat": fix.lat,
        "lon": fix.lon,
        "alt_msl": fix.alt_msl if fix.sentence == "GGA" else None,
        "quality": fix.quality,
        "sats": fix.sats,
        "hdop": fix.hdop,
        "speed_mps": fix.speed_mps if fix.sentence == "RMC" else None,
        "track_deg": fix.track_deg if fix.sentence == "RMC" else None,
    }


def decode_lines(lines: list[bytes], out: TextIO, gps: Optional[NmeaGps] = None) -> NmeaGps:
    """Feed raw log lines (bytes, no comments removed yet) through a driver; print one JSON line per fix."""
    driver = gps if gps is not None else NmeaGps(None, SimClock())
    for number, raw in enumerate(lines, start=1):
        # latin-1 keeps every byte as one character, so binary noise reaches the driver intact.
        text = raw.decode("latin-1").rstrip("\r\n")
        if text.startswith("#"):
            continue
        # The line number stands in for the clock: it only orders events, nothing is printed with it.
        for fix in driver.feed_sentences(text, float(number)):
            out.write(json.dumps(fix_to_record(fix)) + "\n")
    return driver


def decode_file(path: str, out: TextIO, err: TextIO) -> int:
    """Decode the NMEA log at ``path``: fixes as JSON lines on ``out``, one summary line on ``err``.

    Returns 0 on success, 2 when the file cannot be read (with a message naming it).
    """
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as exc:
        reason = exc.strerror or str(exc)
        err.write(f"beastbt gps decode: cannot read {path}: {reason}\n")
        return 2
    driver = decode_lines(data.split(b"\n"), out)
    err.write(f"{path}: {driver.stats.summary()}\n")
    return 0
