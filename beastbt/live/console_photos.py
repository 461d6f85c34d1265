"""The run's photos in the operator console: the newest ones in the state, the JPEG files served by the console.

A mission's ``photo:`` step (and an ``alert:`` with ``photo: true``) saves a JPEG in the run folder
(:mod:`beastbt.behaviours.photo`) and notes it in the vision watch's :class:`~beastbt.vision.watch.PhotoLog`.
Here:

* :class:`PhotoNotes` (the run's process, tick thread): the state's ``photos`` (how many, the newest few with
  their name, time and address) and ``alert`` (the newest alert, with the address of the photo it took), and
  the photos not yet told to the console's process (their file's path, sent over the pipe);
* :class:`PhotoShelf` (the console's process): the photos it was told of, by file name. ``GET /api/photos``
  lists them; ``GET /api/photos/NAME.jpg`` answers a file's bytes only when NAME.jpg is one of them, so no
  request can reach any other file (a name with ``/``, ``\\`` or ``..`` is not looked up at all).
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any, Optional

PHOTOS_SHOWN = 6
"""The newest photos the state carries (the page shows the newest large, these as a strip); ``GET /api/photos``
lists every one."""
PHOTO_URL = "/api/photos/"
"""Where the console serves a photo: this, then the file's name (``gate.jpg``; ``gate-2.jpg`` for a second one)."""


def photo_url(file: Optional[str]) -> Optional[str]:
    """The console's address of a saved photo's file (None when it was not saved)."""
    return None if not file else PHOTO_URL + Path(file).name


class PhotoNotes:
    """What the console's state says of the run's photos and alerts (built on the tick thread).

    ``run`` is the mission's run: its vision watch's photo log (absent for a mission without the camera's
    words) and its event log, whose ``alert`` events this listens to.
    """

    def __init__(self, run: Any) -> None:
        self.run = run
        self.told = 0
        """How many photos of the log the console's process has been told of."""
        self.served: set[str] = set()
        """The files told of (they were there when told): only these get an address in the state."""
        self.alert: Optional[dict] = None
        """The newest alert: ``{time_s, text, photo}`` (``photo`` the address of the photo it took, or None)."""
        run.events.listeners.append(self._on_event)

    def _photos(self) -> list[dict]:
        watch = getattr(self.run.ctx.services, "vision", None)
        return watch.log.photos if watch is not None else []

    def _on_event(self, event: Any) -> None:
        if event.kind != "alert":
            return
        # The alert's photo is the newest one, taken just before the event (RaiseAlert names its file in the text).
        photos = self._photos()
        shot = photos[-1] if photos else None
        said = f" (photo {shot['file']})" if shot is not None and shot.get("file") else None
        url = photo_url(shot["file"]) if said and event.text.endswith(said) and os.path.isfile(shot["file"]) else None
        text = event.text[:-len(said)] if url else event.text  # the banner shows the picture, not its path
        self.alert = {"time_s": round(event.time_s, 1), "text": text, "photo": url}

    def state(self) -> dict:
        """The state's ``photos`` (``{count, latest: [{name, time_s, url}]}``, newest last; ``url`` null until the
        console's process has been told of the file, or when it was not saved) and ``alert``."""
        photos = self._photos()
        served = self.served
        latest = [{"name": p["name"], "time_s": p["time_s"],
                   "url": photo_url(p.get("file")) if p.get("file") in served else None}
                  for p in photos[-PHOTOS_SHOWN:]]
        return {"photos": {"count": len(photos), "latest": latest}, "alert": self.alert}

    def untold(self) -> list[tuple]:
        """The ``("photo", file_name, name, time_s, path)`` messages for the photos saved since the last call."""
        photos = self._photos()
        # a file that is not there (a replay names the photo it does not write again) is not offered to the page
        fresh = [p for p in photos[self.told:] if p.get("file") and os.path.isfile(p["file"])]
        self.told = len(photos)
        self.served.update(p["file"] for p in fresh)
        return [("photo", Path(p["file"]).name, p["name"], p["time_s"], str(p["file"])) for p in fresh]


class PhotoShelf:
    """The photos the console serves (the console's process): file name -> (name, time_s, path).

    Added to from the pipe's thread, read by the web server's: a lock keeps each look-up whole.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._photos: dict[str, tuple[str, float, str]] = {}

    def add(self, file_name: str, name: str, time_s: float, path: str) -> None:
        """A photo the run saved: served as ``/api/photos/<file_name>`` from ``path``."""
        with self._lock:
            self._photos[file_name] = (name, float(time_s), path)

    def listing(self) -> list[dict]:
        """Every photo, oldest first: ``{name, time_s, url}``."""
        with self._lock:
            items = list(self._photos.items())
        return [{"name": name, "time_s": t, "url": PHOTO_URL + file} for file, (name, t, _) in items]

    def path_of(self, file_name: str) -> Optional[str]:
        """The path of the photo served as ``file_name``, or None (an unknown name, or one that is not a plain file
        name: never looked up)."""
        if not file_name or "/" in file_name or "\\" in file_name or ".." in file_name or "\x00" in file_name:
            return None
        with self._lock:
            entry = self._photos.get(file_name)
        return entry[2] if entry is not None else None


__all__ = ["PhotoNotes", "PhotoShelf", "photo_url", "PHOTOS_SHOWN", "PHOTO_URL"]
