"""What the detectors found, frame by frame, in a small JSON-ready form: what the views draw.

A :class:`DetectionFeed` listens to the run's :class:`~beastbt.vision.watch.VisionWatch`
(:meth:`DetectionFeed.attach`) and keeps, for each camera frame a detector looked at, one
*frame entry*::

    {"seq": 41, "stamp_s": 12.3, "size": [320, 240],
     "tags": [{"family": "apriltag_36h11", "id": 0, "corners": [[u, v] x4], "size_m": 0.3,
               "position_m": [x, y, z], "facing_rad": 3.1, "distance_m": 1.2}],
     "qr": [{"text": "door-3", "corners": [[u, v] x4]}],
     "colour": [{"name": "red", "box": [x, y, w, h], "area_frac": 0.02}],
     "motion": {"box": [x, y, w, h], "area_frac": 0.01, "moving": true, "warm": true}}

Pixels are the frame's own (``size``: its width and height), positions the robot's base frame
(x forward, y left, z up, m), angles rad. A kind is present only while its detector is awake:
it ran on this frame, or ran no longer than :data:`HOLD_S` before it (the QR reader reads twice a
second; its last read is carried to the frames between, so that a view does not flicker). When no
detector has run for :data:`HOLD_S`, :meth:`DetectionFeed.take` gives one last entry with no kind
(``seq`` -1): the views clear what they drew.

The recording (``/camera/detections``, ``/camera/tags``: :mod:`beastbt.recording.detection_views`) and
the console's overlay each attach a feed of their own. Nothing here touches devices or the clock: times
are the frames' stamps and the caller's ``now_s`` (clock seconds).
"""

from __future__ import annotations

from typing import Any, Optional

HOLD_S = 0.5
"""A detector's answer stays in the entries of the frames that follow it for this long (clock s)."""
MAX_PENDING = 16
"""Frame entries kept between two :meth:`DetectionFeed.take` calls (the oldest go first)."""


def _corners(points: Any) -> list[list[float]]:
    """Four image corners as ``[[u, v], ...]`` rounded to 0.1 px (enough for a drawing, and short)."""
    return [[round(float(u), 1), round(float(v), 1)] for u, v in points]


def compact(kind: str, value: Any) -> Optional[tuple[str, Any]]:
    """A detector's answer (``kind`` as :class:`~beastbt.vision.watch.VisionWatch` names it) as the entry's
    ``(field, value)``: ``tags``, ``qr``, ``colour`` lists or the ``motion`` dict; None for no answer."""
    if value is None:
        return None
    if kind.startswith("tags:"):
        return "tags", [{"family": t.family, "id": int(t.id), "corners": _corners(t.corners_px),
                         "size_m": round(float(t.size_m), 4),
                         "position_m": None if t.position_m is None else [round(float(c), 4) for c in t.position_m],
                         "facing_rad": None if t.facing_rad is None else round(float(t.facing_rad), 4),
                         "distance_m": round(float(t.distance_m), 3)} for t in value]
    if kind == "qr":
        return "qr", [{"text": q.text, "corners": _corners(q.corners_px)} for q in value]
    if kind.startswith("colour:"):
        blob = value[0]
        name = kind.split(":", 1)[1]
        if blob is None:
            return "colour", []
        return "colour", [{"name": name, "box": [int(b) for b in blob.box_px], "area_frac": round(blob.area_frac, 4)}]
    if kind == "motion":
        return "motion", {"box": None if value.box_px is None else [int(b) for b in value.box_px],
                          "area_frac": round(float(value.area_frac), 4), "moving": bool(value.moving),
                          "warm": bool(value.warm)}
    return None


class DetectionFeed:
    """The frame entries of one view (see the module docstring); fed by the watch, emptied by :meth:`take`."""

    def __init__(self, hold_s: float = HOLD_S) -> None:
        self.hold_s = float(hold_s)
        self._pending: dict[int, dict] = {}
        """seq -> {"stamp_s", "size", "answers": {kind key: (field, value)}} of frames not taken yet."""
        self._newest: dict[str, tuple[float, tuple[str, Any]]] = {}
        """kind key -> (stamp of its frame, (field, value)): the answers carried to later frames."""
        self._last_s: Optional[float] = None
        """Stamp of the newest frame taken; None once the views were cleared (or before any)."""
        self._size: list[int] = [0, 0]

    @classmethod
    def attach(cls, watch: Any, hold_s: float = HOLD_S) -> "DetectionFeed":
        """A feed told every answer of ``watch`` (a :class:`~beastbt.vision.watch.VisionWatch`)."""
        feed = cls(hold_s)
        watch.listeners.append(feed.on_result)
        return feed

    def on_result(self, kind: str, frame: Any, value: Any) -> None:
        """One detector's answer ``value`` of ``kind`` on ``frame`` (a CameraFrame)."""
        entry = self._pending.get(frame.seq)
        if entry is None:
            if len(self._pending) >= MAX_PENDING:
                self._pending.pop(min(self._pending))
            shape = frame.image.shape
            entry = self._pending[frame.seq] = {"stamp_s": float(frame.stamp_s), "size": [int(shape[1]),
                                                                                          int(shape[0])],
                                                "answers": {}}
        field = compact(kind, value)
        if field is not None:
            entry["answers"][kind] = field

    def take(self, now_s: float) -> list[dict]:
        """The frame entries made since the last call, oldest first; or one empty entry (``seq`` -1, stamped
        ``now_s``) when no detector ran for ``hold_s`` after the last one; else ``[]``."""
        out: list[dict] = []
        for seq in sorted(self._pending):
            entry = self._pending[seq]
            stamp = entry["stamp_s"]
            for kind, field in entry["answers"].items():
                self._newest[kind] = (stamp, field)
            fields: dict[str, Any] = {}
            for kind, (seen_s, (name, value)) in self._newest.items():
                if stamp - seen_s > self.hold_s:
                    continue
                if name == "motion":
                    fields["motion"] = value
                else:
                    fields.setdefault(name, []).extend(value)
            out.append({"seq": seq, "stamp_s": stamp, "size": entry["size"], **fields})
            self._last_s = stamp
            self._size = entry["size"]
        self._pending.clear()
        if not out and self._last_s is not None and now_s - self._last_s > self.hold_s:
            self._last_s = None
            self._newest.clear()
            out.append({"seq": -1, "stamp_s": float(now_s), "size": self._size})
        return out


__all__ = ["DetectionFeed", "HOLD_S", "compact"]
