"""``beastbt run --foxglove PORT``: the recording's channels served live over the Foxglove WebSocket protocol.

A real run (the patrol at real-time pace, recorded to a file as well) serves
on a free port; a plain WebSocket client speaks the protocol to it
(subprotocol ``foxglove.sdk.v1``): it sees every channel advertised with the
recording's schema, subscribes, and gets messages that are, byte for byte
and log time for log time, those the file holds.
"""

from __future__ import annotations

import asyncio
import json
import socket
import struct
import subprocess
import sys
import time

import jsonschema
import pytest

from beastbt.recording.reader import read_recording
from beastbt.recording.schemas import CHANNELS, schema_bytes
from conftest import REPO

websockets = pytest.importorskip("websockets", reason="the live test's client (pip install -e '.[test]')")

SUBSCRIBE = ("/tf", "/cmd/gate", "/scene", "/gps/fix")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def client(port: int, seconds: float) -> tuple[str, dict, list[tuple[str, int, bytes]]]:
    """Connect (retrying while the run starts), read the advertisement, subscribe, collect messages."""
    deadline = time.monotonic() + 30.0
    while True:
        try:
            ws = await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"])
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.1)
    async with ws:
        channels: dict = {}
        while not channels:
            op = json.loads(await asyncio.wait_for(ws.recv(), 10.0))
            if op["op"] == "advertise":
                channels = {c["topic"]: c for c in op["channels"]}
        by_id = {}
        subs = []
        for i, topic in enumerate(SUBSCRIBE):
            by_id[i] = topic
            subs.append({"id": i, "channelId": channels[topic]["id"]})
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        got: list[tuple[str, int, bytes]] = []
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                frame = await asyncio.wait_for(ws.recv(), 1.0)
            except asyncio.TimeoutError:
                continue
            if isinstance(frame, bytes) and frame[0] == 1:  # MessageData: sub id u32, log time u64, payload
                sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                got.append((by_id[sub_id], log_time, frame[13:]))
        return ws.subprotocol, channels, got


def test_a_client_sees_every_channel_and_the_messages_of_the_recording(tmp_path):
    port = free_port()
    record = tmp_path / "live.mcap"
    run = subprocess.Popen([sys.executable, "-m", "beastbt", "run", str(REPO / "missions" / "patrol.yaml"),
                            "--speed", "realtime", "--max-time", "8 s", "--no-record", "--record", str(record),
                            "--foxglove", str(port)], cwd=tmp_path, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        protocol, channels, got = asyncio.run(client(port, seconds=4.0))
    finally:
        out, err = run.communicate(timeout=60)
    assert run.returncode == 1, err  # stopped by --max-time
    assert f"ws://127.0.0.1:{port}" in out and not (tmp_path / "runs").exists()
    assert protocol == "foxglove.sdk.v1"
    # Every channel of the recording, with the recording's schema.
    assert set(CHANNELS) <= set(channels)
    for topic, schema in CHANNELS.items():
        c = channels[topic]
        assert (c["encoding"], c["schemaEncoding"], c["schemaName"]) == ("json", "jsonschema", schema["title"])
        assert json.loads(c["schema"]) == json.loads(schema_bytes(schema))
    # Messages arrive on what was subscribed: every tick's /tf and /cmd/gate, the latched /scene.
    topics = {topic for topic, _, _ in got}
    assert {"/tf", "/cmd/gate", "/scene"} <= topics, topics
    assert sum(topic == "/cmd/gate" for topic, _, _ in got) > 20  # 20 Hz for seconds
    # The same bytes at the same log times as the file (a resent /scene is live only and carries a newer time).
    recording = read_recording(record)
    offset = recording.log_time_offset_ns
    in_file = {(topic, t + offset, json.dumps(m, sort_keys=True)) for topic in SUBSCRIBE
               for t, m in recording.messages.get(topic, [])}
    for topic, log_time, payload in got:
        assert log_time > 1_577_836_800 * 10**9
        if topic != "/scene":
            assert (topic, log_time, json.dumps(json.loads(payload), sort_keys=True)) in in_file, topic
    tf = next(json.loads(p) for topic, _, p in got if topic == "/tf")
    jsonschema.Draft202012Validator(CHANNELS["/tf"]).validate(tf)


def test_a_taken_port_is_said_and_the_run_goes_on(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = subprocess.run([sys.executable, "-m", "beastbt", "run", str(REPO / "missions" / "patrol.yaml"),
                              "--max-time", "2 s", "--runs-dir", str(tmp_path / "runs"), "--foxglove", str(port)],
                             cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 1  # stopped by --max-time, as without --foxglove
    assert f"--foxglove could not listen on 127.0.0.1:{port}" in run.stderr
    (folder,) = (tmp_path / "runs").iterdir()
    assert read_recording(folder / "run.mcap").complete  # the recording is whole


def test_the_option_takes_host_and_port():
    bad = subprocess.run([sys.executable, "-m", "beastbt", "run", str(REPO / "missions" / "patrol.yaml"),
                          "--foxglove", "localhost:notaport"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--foxglove takes [HOST:]PORT" in bad.stderr
