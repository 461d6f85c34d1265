"""The console's photo endpoints over HTTP: only the run's photos, and only with the console's guard.

The console's web server (:class:`~beastbt.live.console_server.ConsoleServer`) is started in this process with
the token required, and told of one photo as the run tells it (:class:`~beastbt.live.console_photos.PhotoShelf`);
beside the photo lies a file it was not told of. A real run's photos in a real browser are in
``test_console_photos_browser.py``.
"""

from __future__ import annotations

import http.client
import json
from pathlib import Path

import pytest

from beastbt.live.console_process import RemoteState
from beastbt.live.console_server import ConsoleServer

JPEG = b"\xff\xd8\xff\xe0 a photo \xff\xd9"


@pytest.fixture
def console(tmp_path: Path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "gate.jpg").write_bytes(JPEG)
    (folder / "secret.jpg").write_bytes(b"not a photo the run took")
    (tmp_path / "outside.jpg").write_bytes(b"outside the run folder")
    server = ConsoleServer(RemoteState(0, "{}"), controls=None, video=None, map_source=dict, host="127.0.0.1",
                           port=0, token="the-token", require_token=True).start()
    server.photos.add("gate.jpg", "gate", 0.5, str(folder / "gate.jpg"))
    yield server
    server.close()


def get(server: ConsoleServer, path: str, token: bool = True) -> tuple[int, str, bytes]:
    """(status, content type, body) of a raw GET (the path sent as written: no client normalises its dots)."""
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    conn.request("GET", path, headers={"Authorization": "Bearer the-token"} if token else {})
    r = conn.getresponse()
    body = r.read()
    conn.close()
    return r.status, r.getheader("Content-Type", ""), body


def test_a_photo_the_run_took_is_served_and_listed_with_the_token(console):
    status, kind, body = get(console, "/api/photos/gate.jpg")
    assert (status, kind, body) == (200, "image/jpeg", JPEG)
    status, _, body = get(console, "/api/photos")
    assert status == 200 and json.loads(body) == {"photos": [{"name": "gate", "time_s": 0.5,
                                                              "url": "/api/photos/gate.jpg"}]}


@pytest.mark.parametrize("path", ["/api/photos/gate.jpg", "/api/photos"])
def test_without_the_token_the_photos_are_refused(console, path):
    status, _, body = get(console, path, token=False)
    assert status == 401 and "token" in json.loads(body)["error"]


@pytest.mark.parametrize("path", [
    "/api/photos/secret.jpg",            # in the run folder, but not a photo the run took
    "/api/photos/..%2Foutside.jpg",      # an encoded slash: one segment for the router, a path outside once decoded
    "/api/photos/..%2Frun%2Fgate.jpg",
    "/api/photos/%2E%2E%2Foutside.jpg",
    "/api/photos/..",
    "/api/photos/gate.jpg%00",
    "/api/photos/sub%2Fgate.jpg",
    "/api/photos/..%5Coutside.jpg",
])
def test_only_the_runs_photos_are_served_never_another_file(console, path):
    status, _, body = get(console, path)
    assert status == 404, (path, status, body)
    assert b"outside the run folder" not in body and b"not a photo" not in body


def test_the_state_offers_only_photos_whose_file_is_there_and_pairs_an_alert_with_its_photo(tmp_path: Path):
    from types import SimpleNamespace

    from beastbt.core.events import Event
    from beastbt.live.console_photos import PhotoNotes
    from beastbt.vision.watch import PhotoLog
    (tmp_path / "gate.jpg").write_bytes(JPEG)
    (tmp_path / "alert-1.jpg").write_bytes(JPEG)
    log = PhotoLog()
    run = SimpleNamespace(ctx=SimpleNamespace(services=SimpleNamespace(vision=SimpleNamespace(log=log))),
                          events=SimpleNamespace(listeners=[]))
    notes = PhotoNotes(run)
    assert notes.state() == {"photos": {"count": 0, "latest": []}, "alert": None}
    log.photos += [{"name": "gate", "time_s": 1.0, "file": str(tmp_path / "gate.jpg")},
                   {"name": "door", "time_s": 2.0, "file": "(replay) door.jpg"},  # a replay writes no file
                   {"name": "full", "time_s": 3.0, "file": None}]  # a full disk
    assert [m[:2] for m in notes.untold()] == [("photo", "gate.jpg")] and notes.untold() == []
    assert [p["url"] for p in notes.state()["photos"]["latest"]] == ["/api/photos/gate.jpg", None, None]
    log.photos.append({"name": "alert-1", "time_s": 4.0, "file": str(tmp_path / "alert-1.jpg")})
    run.events.listeners[0](Event(4.0, "alert", f"someone at the gate (photo {tmp_path / 'alert-1.jpg'})"))
    assert notes.state()["alert"] == {"time_s": 4.0, "text": "someone at the gate", "photo": "/api/photos/alert-1.jpg"}
    run.events.listeners[0](Event(5.0, "alert", "no camera (no photo: no camera frame)"))
    assert notes.state()["alert"] == {"time_s": 5.0, "text": "no camera (no photo: no camera frame)", "photo": None}
