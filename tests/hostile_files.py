"""Hostile route files and joystick scripts shared by tests/test_hardening_sizes.py and benchmarks/file_limits.py
(issue 38): written to disk piece by piece, so that neither the test nor the benchmark holds them in memory, and
without a pytest import, so that the benchmark's parent process stays small."""

from __future__ import annotations

from pathlib import Path


def write_gpx(path: Path, points: int) -> None:
    """A GPX track of ``points`` trkpts with elevations (2 million: the probe's 78 MB, here about 90 MB)."""
    with open(path, "w") as f:
        f.write('<?xml version="1.0"?>\n<gpx version="1.1" creator="probe" xmlns="http://www.topografix.com/GPX/1/1">'
                "<trk><trkseg>\n")
        for chunk in range(0, points, 10_000):
            f.write("".join(f'<trkpt lat="40.{i % 10000:04d}" lon="-3.{i % 7000:04d}"><ele>650</ele></trkpt>\n'
                            for i in range(chunk, min(points, chunk + 10_000))))
        f.write("</trkseg></trk></gpx>\n")


def write_kml(path: Path, points: int) -> None:
    """A KML LineString of ``points`` lon,lat,alt tuples, ten a line (2 million: the probe's 38 MB, here more)."""
    with open(path, "w") as f:
        f.write('<?xml version="1.0"?>\n<kml xmlns="http://www.opengis.net/kml/2.2"><Placemark><LineString>'
                "<coordinates>\n")
        for chunk in range(0, points, 10_000):  # ten tuples a line
            f.write("".join(f"-3.{i % 7000:04d},40.{i % 10000:04d},0" + ("\n" if i % 10 == 9 else " ")
                            for i in range(chunk, min(points, chunk + 10_000))))
        f.write("</coordinates></LineString></Placemark></kml>\n")


def write_script(path: Path, events: int) -> None:
    """A joystick script of ``events`` stick events, one a line (2 million: the probe's 63 MB)."""
    with open(path, "w") as f:
        for chunk in range(0, events, 10_000):
            f.write("".join(f"- {{at: {i * 0.01:.2f} s, linear: 0.5}}\n"
                            for i in range(chunk, min(events, chunk + 10_000))))
