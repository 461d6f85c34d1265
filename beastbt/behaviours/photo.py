"""``photo`` and ``alert``: a full-resolution picture in the run folder, and telling the operator something is wrong.

A photo is the camera's newest frame as it came (no line-detector reduction), saved as
``<name>.jpg`` in the run folder by the run's snapshot saver (the recording attaches it; the report
shows it), with an event of kind ``photo``. An alert is an event of kind ``alert`` (the console, the
station and the recording show events) and an entry in the summary's ``alerts``. Photos are kept in
:class:`~beastbt.vision.watch.PhotoLog` (``ctx.services.vision.log``) for the summary.
"""

from __future__ import annotations

from typing import Any, Optional

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext

FRAME_WAIT_S = 1.0
"""A photo waits this long (s) for a fresh frame (the camera may just have been switched on) before it fails."""


def save_photo(ctx: MissionContext, name: str, now_s: float) -> Optional[dict[str, Any]]:
    """Save the newest fresh frame as ``name``; the photo's entry (``file`` None when the run keeps no files), or
    None without a fresh frame."""
    watch = ctx.services.vision
    frame = None if watch is None else watch.frame(now_s)
    if frame is None:
        return None
    entry: dict[str, Any] = {"name": name, "time_s": round(now_s, 3), "file": None,
                             "size_px": [int(frame.image.shape[1]), int(frame.image.shape[0])]}
    save = ctx.services.save_snapshot
    if save is not None:
        try:
            entry["file"] = save(name, frame)
        except OSError as exc:  # a full disk does not stop the mission: the photo is noted as not saved
            entry["error"] = str(exc.strerror or exc)
    watch.log.photos.append(entry)
    where = entry["file"] or f"not saved ({entry.get('error', 'the run keeps no files')})"
    ctx.events.add("photo", f"{name}: {where}")
    return entry


class TakePhoto(BeastBehaviour):
    """Save the camera's newest frame at full resolution as ``<name>.jpg`` in the run folder.

    Succeeds once saved (or noted as not saved: a full disk does not stop the mission); waits up to
    :data:`FRAME_WAIT_S` for a fresh frame and fails when none comes.
    """

    def __init__(self, name: str, ctx: MissionContext, label: str) -> None:
        super().__init__(name, ctx)
        self.label = label
        self.started_s = 0.0

    def initialise(self) -> None:
        self.started_s = self.now()

    def update(self) -> Status:
        if save_photo(self.ctx, self.label, self.now()) is not None:
            return Status.SUCCESS
        if self.now() - self.started_s >= FRAME_WAIT_S:
            return self.fail("no camera frame")
        self.feedback_message = "waiting for a camera frame"
        return Status.RUNNING


class RaiseAlert(BeastBehaviour):
    """Raise an alert: an event of kind ``alert`` and a summary entry; with ``photo`` a photo named ``alert-N``.

    Succeeds at once (a photo it cannot take is noted in the alert, never a failure: the alert matters more).
    """

    def __init__(self, name: str, ctx: MissionContext, text: str, photo: bool) -> None:
        super().__init__(name, ctx)
        self.text = text
        self.photo = photo

    def update(self) -> Status:
        now = self.now()
        watch = self.ctx.services.vision
        entry: dict[str, Any] = {"time_s": round(now, 3), "text": self.text, "photo": None}
        if self.photo:
            n = 1 + (watch.log.alert_photos if watch is not None else 0)
            if watch is not None:
                watch.log.alert_photos += 1
            shot = save_photo(self.ctx, f"alert-{n}", now)
            entry["photo"] = shot["file"] if shot is not None else None
        with_photo = f" (photo {entry['photo']})" if entry["photo"] else (" (no photo: no camera frame)"
                                                                         if self.photo else "")
        self.ctx.events.add("alert", self.text + with_photo)
        return Status.SUCCESS


__all__ = ["TakePhoto", "RaiseAlert", "save_photo", "FRAME_WAIT_S"]
