"""``beastbt foxglove-layout``: print the Foxglove layout for beastbt's channels (save it, then import it).

``beastbt foxglove-layout > beastbt.json`` and, in Foxglove, Layouts ->
Import from file: a 3D view following the robot (the scene, the frames, the
fused pose), the map (GPS fixes, the fused position, the route and fences),
the camera with the line detector's annotations, plots of speed and of the
errors, and the log. It works for a recording (``runs/.../run.mcap``) and for
a live run (``beastbt run MISSION --foxglove PORT``) alike.
"""

from __future__ import annotations

import argparse
import json
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt foxglove-layout``."""
    p.add_argument("--robot", default=None, metavar="PROFILE",
                   help="use the frame names of this robot profile's frames: section (default: the standard "
                        "map, base_link...)")


def command(args: argparse.Namespace) -> int:
    """Print the layout (JSON) on standard output."""
    from beastbt.core.errors import InvalidInput, plain_reason
    from beastbt.recording.layout import foxglove_layout
    frames = None
    if args.robot:
        from beastbt.recording.config import FramesConfig
        from beastbt.robot.profile import load_profile, section_config
        try:
            frames = section_config(load_profile(args.robot), "frames", FramesConfig)
        except InvalidInput as exc:
            print(exc.format(), file=sys.stderr)  # positioned already: FILE:LINE:COL: error: ...
            return 2
        except OSError as exc:
            print(f"beastbt foxglove-layout: error: {args.robot}: {plain_reason(exc)}", file=sys.stderr)
            return 2
    json.dump(foxglove_layout(frames), sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0
