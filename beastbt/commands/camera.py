"""``beastbt camera ACTION``: camera tools. ``camera calibrate PHOTOS... --board 9x6 --square 25mm`` finds the
camera's intrinsics from checkerboard photos (:mod:`beastbt.vision.calibration`).

``calibrate`` prints fx, fy, cx, cy, the distortion and the RMS reprojection error (pixels); with ``--profile
robots/x.yaml`` it writes them into that profile's ``camera.intrinsics:`` in place (ruamel.yaml's round trip:
comments and layout kept), with ``-o FILE`` into a YAML file of its own to paste. Exit status: 0 done, 2 bad
input (an unreadable photo, photos of different sizes, too few photos showing the board, a bad option or
profile), nothing written.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any, Callable, Optional

EXIT_SUCCESS, EXIT_INVALID = 0, 2
PROG = "beastbt camera calibrate"


def add_calibrate_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt camera calibrate``."""
    p.add_argument("photos", nargs="+", metavar="PHOTO",
                   help="checkerboard photos (JPEG, PNG...) from the robot's camera, at its size, the whole board "
                        "in each, tilted differently; at least 5")
    p.add_argument("--board", required=True, metavar="COLSxROWS",
                   help="the board's inner corners, e.g. 9x6 (a board of 10x7 squares)")
    p.add_argument("--square", required=True, metavar="SIZE", help="the side of one square, e.g. 25mm or 2.5 cm")
    p.add_argument("--profile", metavar="PROFILE", default=None,
                   help="a robot profile whose camera.intrinsics: to write in place (comments and layout kept)")
    p.add_argument("-o", "--out", metavar="FILE", default=None,
                   help="a YAML file to write camera: {intrinsics: ...} to, to paste into a profile")


def _error(message: str) -> int:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return EXIT_INVALID


def _report(cal: Any) -> str:
    """The calibration in words, for standard output."""
    c = cal.intrinsics
    k1, k2, p1, p2, *k3 = c.distortion
    lines = [f"photos: {len(cal.used)} used" + (f", {len(cal.skipped)} without the board" if cal.skipped else ""),
             *(f"  skipped {path}: {why}" for path, why in cal.skipped),
             f"image: {c.width_px}x{c.height_px} px",
             f"fx: {c.fx_px:.2f} px   fy: {c.fy_px:.2f} px",
             f"cx: {c.cx_px:.2f} px   cy: {c.cy_px:.2f} px",
             f"distortion (k1 k2 p1 p2 k3): {k1:.5f} {k2:.5f} {p1:.5f} {p2:.5f} {k3[0] if k3 else 0.0:.5f}",
             f"RMS reprojection error: {c.rms_px:.3f} px" + ("" if c.rms_px <= 1.0 else
                                                             " (over 1 px: blurred photos or a board not flat?)")]
    return "\n".join(lines)


def _flow(values: list) -> Any:
    """A list written on one line (``[k1, k2, p1, p2, k3]``), as a person writes a short list."""
    from ruamel.yaml.comments import CommentedSeq
    seq = CommentedSeq(values)
    seq.fa.set_flow_style()
    return seq


def profile_with_intrinsics(text: str, section: dict) -> str:
    """``text`` (a robot profile) with ``camera.intrinsics:`` set to ``section``, everything else as it was.

    Raises :class:`~beastbt.core.yaml_round_trip.EditRefused` when the text is not a YAML mapping or has no
    ``camera:`` mapping (a calibration belongs to a camera the profile has)."""
    from ruamel.yaml.comments import CommentedMap

    from beastbt.core.yaml_round_trip import EditRefused, dump, load_round_trip, patched
    crlf = "\r\n" in text
    work = text.replace("\r\n", "\n") if crlf else text
    if not work.endswith("\n"):
        work += "\n"
    y, data, exact = load_round_trip(work)
    baseline = work if exact else dump(y, data)
    camera = data.get("camera")
    if not isinstance(camera, dict):
        raise EditRefused("the profile has no camera: section to calibrate; add one (camera: {device: /dev/video0})",
                          1, 1)
    node = CommentedMap()
    for key, value in section.items():
        node[key] = _flow(value) if isinstance(value, list) else value
    camera["intrinsics"] = node
    new = dump(y, data)
    if not exact:
        new = patched(work, baseline, new) or new
    return new.replace("\n", "\r\n") if crlf else new


def intrinsics_yaml(section: dict) -> str:
    """``camera: {intrinsics: section}`` as block YAML (the distortion on one line), to paste into a profile."""
    import io

    from ruamel.yaml import YAML
    from ruamel.yaml.comments import CommentedMap
    node = CommentedMap((k, _flow(v) if isinstance(v, list) else v) for k, v in section.items())
    y = YAML(typ="rt")
    y.indent(mapping=2, sequence=4, offset=2)
    out = io.StringIO()
    y.dump(CommentedMap(camera=CommentedMap(intrinsics=node)), out)
    return out.getvalue()


def _write_atomically(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file beside it and a rename (never half a file)."""
    tmp = path.with_name(f".{path.name}.calibrate-tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def _checked_profile(path: str) -> tuple[Optional[str], Optional[int]]:
    """(the profile's text, None), or (None, exit status after saying why it cannot be written)."""
    target = Path(path)
    if not target.is_file():
        return None, _error(f"--profile {path}: no such file")
    try:
        return target.read_text(encoding="utf-8"), None
    except (OSError, UnicodeDecodeError) as exc:
        return None, _error(f"--profile {path}: cannot be read ({exc})")


def calibrate_command(args: argparse.Namespace) -> int:
    """Calibrate from the photos, print the result, write it where asked; 2 on bad input (nothing written)."""
    from beastbt.commands.paths import output_file_problem
    from beastbt.core.yaml_round_trip import EditRefused
    from beastbt.vision.calibration import Board, CalibrationRefused, calibrate

    try:
        board = Board.parse(args.board, args.square)
    except ValueError as exc:
        return _error(str(exc))
    problem = output_file_problem("-o", args.out)
    if problem is not None:
        return _error(problem)
    text: Optional[str] = None
    if args.profile:
        text, status = _checked_profile(args.profile)
        if text is None:
            return status or EXIT_INVALID
    try:
        cal = calibrate(args.photos, board)
    except CalibrationRefused as exc:
        return _error(str(exc))
    print(_report(cal))
    section = cal.intrinsics.profile_section()
    if args.profile and text is not None:
        try:
            new = profile_with_intrinsics(text, section)
        except EditRefused as exc:
            where = f"{args.profile}:{exc.line}:{exc.column}" if exc.line is not None else args.profile
            print(f"{where}: error: {exc}", file=sys.stderr)
            return EXIT_INVALID
        _write_atomically(Path(args.profile), new)
        print(f"wrote camera.intrinsics into {args.profile}")
    if args.out:
        header = (f"# beastbt camera calibrate: {len(cal.used)} photos, RMS {cal.intrinsics.rms_px:.3f} px.\n"
                  "# Paste the intrinsics: block under the robot profile's camera: section.\n")
        _write_atomically(Path(args.out), header + intrinsics_yaml(section))
        print(f"wrote {args.out}")
    return EXIT_SUCCESS


ACTIONS: dict[str, tuple[str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]] = {
    "calibrate": ("the camera's intrinsics (fx, fy, cx, cy, distortion) from checkerboard photos, with OpenCV's "
                  "calibration; --profile writes them into a robot profile", add_calibrate_arguments,
                  calibrate_command),
}
"""Action -> (one-line help, add its arguments, run it -> exit status)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``beastbt camera ACTION ...``: one subparser per action of :data:`ACTIONS`."""
    p.description = "Camera tools: " + "; ".join(f"'{n}': {h}" for n, (h, _, _) in ACTIONS.items())
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, (help_text, add, _) in ACTIONS.items():
        add(sub.add_parser(name, help=help_text))


def command(args: argparse.Namespace) -> int:
    """Run the chosen action."""
    return ACTIONS[args.action][2](args)
