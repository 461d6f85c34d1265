"""A detector's answer as a ``/vision/answers`` message: what :mod:`beastbt.vision.recorded_answers` records.

Only numpy here (no OpenCV): the recording's writer process builds the messages
(:func:`answer_message`) without loading the detectors. Positions are metres, angles
radians, pixels the frame's own; every float goes as the float it was (JSON keeps them), arrays with
their numpy dtype, so that a replay gives back the very answer the run got.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

TOPIC = "/vision/answers"
"""The recording's channel of detector answers (one message per detector run; schema
``beastbt.VisionAnswer`` in :mod:`beastbt.recording.schemas`)."""


def _array(a: Any) -> dict:
    arr = np.asarray(a)
    return {"data": arr.tolist(), "dtype": str(arr.dtype)}


def _floats(t: Any) -> Optional[list]:
    return None if t is None else [float(v) for v in t]


def value_json(kind: str, value: Any) -> Any:
    """A detector's answer (as :class:`~beastbt.vision.watch.VisionWatch` keeps it; colour without its camera) as
    JSON-ready data."""
    if value is None:
        return None
    if kind.startswith("tags:"):
        return [{"family": t.family, "id": int(t.id), "corners_px": _array(t.corners_px), "size_m": float(t.size_m),
                 "rvec": _array(t.rvec), "tvec_m": _array(t.tvec_m), "position_m": _floats(t.position_m),
                 "facing_rad": None if t.facing_rad is None else float(t.facing_rad)} for t in value]
    if kind == "qr":
        return [{"text": q.text, "corners_px": _array(q.corners_px)} for q in value]
    if kind == "motion":
        return {"area_frac": float(value.area_frac), "box_px": None if value.box_px is None else
                [int(v) for v in value.box_px], "moving": bool(value.moving), "warm": bool(value.warm)}
    if kind.startswith("colour:"):
        return {"area_frac": float(value.area_frac), "centre_px": _floats(value.centre_px),
                "box_px": [int(v) for v in value.box_px]}
    raise ValueError(f"unknown detector kind {kind!r}")


@dataclass(frozen=True)
class Answer:
    """One detector run: ``kind`` key, the frame's ``seq``, ``stamp_s`` (s) and ``size`` (w, h px), the tick's
    clock time ``now_s`` (s), ``still`` (motion only) and the ``value`` as the watch keeps it."""

    now_s: float
    kind: str
    seq: int
    stamp_s: float
    size: tuple[int, int]
    still: Optional[bool]
    value: Any


def answer_message(a: Answer) -> dict:
    """The ``/vision/answers`` message of an answer (schema ``beastbt.VisionAnswer``); made in the writer process."""
    return {"now_s": a.now_s, "kind": a.kind, "seq": a.seq, "stamp_s": a.stamp_s, "size": list(a.size),
            "still": a.still, "value": value_json(a.kind, a.value)}


__all__ = ["TOPIC", "Answer", "answer_message", "value_json"]
