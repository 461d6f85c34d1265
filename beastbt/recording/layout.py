"""The Foxglove layout shipped with beastbt (``foxglove_layout/beastbt.json``), for ``beastbt foxglove-layout``.

The file is Foxglove's layout JSON (what its Layouts menu imports): panels by
id in ``configById`` and their arrangement in ``layout``. It names beastbt's
channels (:data:`beastbt.recording.schemas.CHANNELS`) and the standard frame
names; :func:`foxglove_layout` puts a robot's own frame names in.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

from beastbt.recording.config import FramesConfig

LAYOUT_FILE = Path(__file__).resolve().parent / "foxglove_layout" / "beastbt.json"


def foxglove_layout(frames: Optional[FramesConfig] = None) -> dict:
    """The layout as a dict, its 3D view following ``frames.base_link`` on a grid in ``frames.map``."""
    layout = json.loads(LAYOUT_FILE.read_text(encoding="utf-8"))
    if frames is not None:
        three_d = layout["configById"]["3D!beastbt"]
        three_d["followTf"] = frames.base_link
        three_d["layers"]["grid"]["frameId"] = frames.map
    return layout


__all__ = ["foxglove_layout", "LAYOUT_FILE"]
