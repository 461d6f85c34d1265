"""The console's process tells the run how many watch its video, including a page that connects the moment the
console listens: the run renders or reads the camera for the console only while that count is above zero, so a
lost count is a page that shows no video for the whole run.

CI once failed so (the console counted no viewer for 30 s with a viewer connected): the count was wired to the
server only after the "ready" had gone out and the video had started, and a "0" said then overwrote the page's
"1". Here the video's start is held until a viewer is connected, which opens that window every time."""
from __future__ import annotations

import asyncio
import dataclasses
import threading
from multiprocessing import Pipe
from typing import Any

import aiohttp

from beastbt.live import console_process
from beastbt.live.console_video import ConsoleVideo, VideoConfig


def _config() -> dict[str, Any]:
    return {"host": "127.0.0.1", "port": 0, "token": None, "require_token": False,
            "video": dataclasses.asdict(VideoConfig(codec="jpeg")), "camera": False, "geometry": None,
            "camera_fps": None, "viewer_camera": None, "state": "{}", "caption": "", "map": {}}


def test_a_viewer_connected_as_soon_as_the_console_listens_is_counted(monkeypatch) -> None:
    viewer_in = threading.Event()
    real_start = ConsoleVideo.start

    def held_start(self: ConsoleVideo) -> ConsoleVideo:
        viewer_in.wait(10)  # the viewer connects while the console's process is still setting up
        return real_start(self)

    monkeypatch.setattr(ConsoleVideo, "start", held_start)
    to_console, inbox = Pipe()
    from_console, outbox = Pipe()
    console = threading.Thread(target=console_process.serve, args=(inbox, outbox), daemon=True)
    console.start()
    to_console.send(("config", _config()))
    assert from_console.poll(10), "the console's process said nothing"
    ready = from_console.recv()
    assert ready[0] == "ready", ready  # the run reads the "ready" first: nothing may come before it
    url = ready[2].rstrip("/")
    leave = threading.Event()
    failed: list[BaseException] = []

    async def watch() -> None:
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(url + "/api/video") as ws:
                viewer_in.set()
                while not leave.is_set():
                    try:
                        await ws.receive(timeout=0.1)
                    except asyncio.TimeoutError:
                        pass

    def viewer() -> None:
        try:
            asyncio.run(watch())
        except BaseException as exc:  # noqa: BLE001 - said by the test's thread
            failed.append(exc)
            viewer_in.set()

    watcher = threading.Thread(target=viewer, daemon=True)
    watcher.start()
    counts: list[int] = []
    try:
        assert viewer_in.wait(10) and not failed, failed
        while from_console.poll(2):  # every count said until the console is quiet
            message = from_console.recv()
            if message[0] == "viewers":
                counts.append(message[1])
        assert counts and counts[-1] == 1, f"the counts the run was told: {counts}"
        leave.set()
        watcher.join(10)
        assert from_console.poll(10)
        assert from_console.recv() == ("viewers", 0)  # and the page that left is counted out
    finally:
        leave.set()
        to_console.send(("close",))
        console.join(10)
    assert not console.is_alive()
