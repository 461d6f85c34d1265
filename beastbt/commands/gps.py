"""``beastbt gps decode FILE``: print the fixes the GPS driver makes of a recorded NMEA log.

One JSON object per line on standard output for every sentence that gives a
position with a valid fix, one summary line on standard error (sentences
read, used, rejected with reasons). Exit status 0, or 2 when the file cannot
be read. The decoding itself is :func:`beastbt.devices.gps_decode.decode_file`.
"""

from __future__ import annotations

import argparse
import os
import sys

from beastbt.devices.gps_decode import decode_file

GPS_ACTIONS = ("decode",)
"""What ``beastbt gps`` can do."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``beastbt gps decode FILE``."""
    p.description = "GPS tools: 'decode FILE' runs a recorded NMEA log through the GPS driver."
    p.add_argument("action", choices=GPS_ACTIONS, help="decode: print one JSON line per fix of a recorded NMEA log")
    p.add_argument("file", help="the NMEA log (raw receiver output; lines starting with '#' are comments)")


def command(args: argparse.Namespace) -> int:
    """GPS tools: decode a recorded NMEA log through the driver (one JSON line per fix)."""
    if args.action != "decode":
        return 2  # argparse rejects other actions before this
    try:
        return decode_file(args.file, sys.stdout, sys.stderr)
    except BrokenPipeError:
        # The reader went away (``beastbt gps decode log | head``): not an error of ours.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0

