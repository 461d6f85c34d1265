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
import logging
import signal
import socket
import struct
import subprocess
import sys
import time

import jsonschema
import pytest

from beastbt.recording.foxglove_live import LATCHED, SdkLogLimiter
from beastbt.recording.reader import read_recording
from beastbt.recording.schemas import CHANNELS, schema_bytes
from conftest import REPO

websockets = pytest.importorskip("websockets", reason="the live test's client (pip install -e '.[test]')")

SUBSCRIBE = ("/tf", "/cmd/gate", "/scene", "/gps/fix", "/collision_monitor/zones")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def connect(port: int) -> "websockets.ClientConnection":
    """Connect to the run's server, retrying while the run starts (for up to 30 s)."""
    deadline = time.monotonic() + 30.0
    while True:
        try:
            return await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"])
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.1)


async def client(port: int, seconds: float) -> tuple[str, dict, list[tuple[str, int, bytes]]]:
    """Connect (retrying while the run starts), read the advertisement, subscribe, collect messages."""
    ws = await connect(port)
    async with ws:
        channels: dict = {}
        while not set(CHANNELS) | set(SUBSCRIBE) <= set(channels):  # advertised over one or several messages
            op = json.loads(await asyncio.wait_for(ws.recv(), 10.0))
            if op["op"] == "advertise":
                channels.update({c["topic"]: c for c in op["channels"]})
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
    # Messages arrive on what was subscribed: every tick's /tf and /cmd/gate, the latched /scene and zones (sent
    # before the client came, and again when it subscribed).
    topics = {topic for topic, _, _ in got}
    assert {"/tf", "/cmd/gate", "/scene", "/collision_monitor/zones"} <= topics, topics
    assert sum(topic == "/cmd/gate" for topic, _, _ in got) > 20  # 20 Hz for seconds
    # The same bytes at the same log times as the file (a resent latched message is live only, with a newer time).
    recording = read_recording(record)
    offset = recording.log_time_offset_ns
    in_file = {(topic, t + offset, json.dumps(m, sort_keys=True)) for topic in SUBSCRIBE
               for t, m in recording.messages.get(topic, [])}
    for topic, log_time, payload in got:
        assert log_time > 1_577_836_800 * 10**9
        if topic not in LATCHED:
            assert (topic, log_time, json.dumps(json.loads(payload), sort_keys=True)) in in_file, topic
    tf = next(json.loads(p) for topic, _, p in got if topic == "/tf")
    jsonschema.Draft202012Validator(CHANNELS["/tf"]).validate(tf)


async def late_map_client(port: int) -> tuple[int, list[bytes]]:
    """Subscribe to /tf alone until a second after its first message (the map went out with the first tick's views,
    which the writer takes after that tick), then to /map alone; returns the /tf messages seen before and the /map
    messages got in the 10 s after (the first ends it)."""
    ws = await connect(port)
    async with ws:
        channels: dict = {}
        while not {"/tf", "/map"} <= set(channels):
            op = json.loads(await asyncio.wait_for(ws.recv(), 10.0))
            if op["op"] == "advertise":
                channels.update({c["topic"]: c for c in op["channels"]})
        tf = {"id": 0, "channelId": channels["/tf"]["id"]}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [tf]}))
        ticks, maps = 0, []
        first_tf = end = None
        give_up = time.monotonic() + 30.0  # no tick in 30 s: the run did not start
        while True:
            now = time.monotonic()
            if (end is not None and now > end) or (first_tf is None and now > give_up):
                return ticks, maps
            if first_tf is not None and end is None and now > first_tf + 1.0:
                end = now + 10.0
                await ws.send(json.dumps({"op": "subscribe",
                                          "subscriptions": [{"id": 1, "channelId": channels["/map"]["id"]}]}))
            try:
                frame = await asyncio.wait_for(ws.recv(), 0.5)
            except asyncio.TimeoutError:
                continue
            if isinstance(frame, bytes) and frame[0] == 1:
                sub_id = struct.unpack_from("<I", frame, 1)[0]
                if sub_id == 0 and end is None:
                    ticks += 1
                    first_tf = first_tf or now
                elif sub_id == 1:
                    maps.append(frame[13:])
                    return ticks, maps


def test_a_client_that_subscribes_to_the_map_alone_late_gets_it(tmp_path):
    """/map goes out once, with the first tick: a client that comes later and subscribes to it alone (no other
    latched topic, which would have had it sent again too) gets it all the same."""
    from localisation_support import mission_text, office_map_file

    office_map_file(tmp_path)
    mission = tmp_path / "stand.yaml"
    mission.write_text(mission_text("stand", "  - wait: 30 s\n"))
    port = free_port()
    run = subprocess.Popen([sys.executable, "-m", "beastbt", "run", str(mission), "--speed", "realtime",
                            "--max-time", "30 s", "--no-record", "--foxglove", str(port)], cwd=tmp_path,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ticks, maps = asyncio.run(late_map_client(port))
    finally:
        run.send_signal(signal.SIGINT)
        run.communicate(timeout=60)
    assert ticks >= 1  # the run had ticked (a standing robot's /tf goes at 1 Hz) a second before: the map had gone out
    assert len(maps) == 1
    grid = json.loads(maps[0])
    jsonschema.Draft202012Validator(CHANNELS["/map"]).validate(grid)
    assert grid["frame_id"] == "map" and grid["column_count"] > 100


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


# -- hostile clients: the run's terminal is not flooded, the run goes on ------------------------------------


def limiter_records(limiter, texts):
    for text in texts:
        limiter.handle(logging.LogRecord("foxglove.websocket.connected_client", logging.ERROR, __file__, 1,
                                         text, None, None))


def test_the_sdk_log_limiter_shows_the_first_of_a_kind_and_counts_the_rest():
    lines: list[str] = []
    now = [0.0]
    limiter = SdkLogLimiter(write=lines.append, clock=lambda: now[0], window_s=10.0, per_client=2, total=6,
                            timer=False)
    unknown = [f"Client 127.0.0.1:5000 attempted to subscribe to unknown channel: {100000 + i}" for i in range(5000)]
    limiter_records(limiter, unknown)
    assert lines == ["beastbt: foxglove: Client 127.0.0.1:5000 attempted to subscribe to unknown channel: 100000"]
    # A second kind from the same client is shown; a third is over the client's two lines.
    limiter_records(limiter, ["Invalid message from 127.0.0.1:5000: expected value at line 1 column 1",
                              "Error receiving from client 127.0.0.1:5000: Message too long"])
    assert len(lines) == 2 and "expected value" in lines[1]
    # The window ends: the next record says what was held back, in one line, then is shown itself.
    now[0] = 10.5
    limiter_records(limiter, unknown[:1])
    assert len(lines) == 4
    assert "5,000 more messages" in lines[2] and "4,999 from 127.0.0.1:5000" in lines[2], lines[2]
    assert "unknown channel: 104999" in lines[2] and "Message too long" in lines[2]
    assert lines[3].endswith("unknown channel: 100000")
    limiter.close()  # nothing more held back: nothing more said
    assert len(lines) == 4


def test_the_sdk_log_limiter_caps_lines_over_all_clients_and_makes_text_safe_for_a_terminal():
    lines: list[str] = []
    limiter = SdkLogLimiter(write=lines.append, clock=lambda: 0.0, window_s=10.0, per_client=2, total=6,
                            timer=False)
    limiter_records(limiter, ["Invalid message from 127.0.0.1:1: unknown variant `\x1b[2J" + "x" * 5_000_000 + "`"])
    limiter_records(limiter, [f"Invalid message from 127.0.0.1:{1000 + i}: expected value" for i in range(500)])
    assert len(lines) == 6 and "\\x1b[2Jxxx" in lines[0]  # the escape shown as text, not obeyed
    limiter.close()
    assert len(lines) == 7 and "495 more" in lines[6] and "from 495 client(s) in all" in lines[6], lines[6]
    assert all("\x1b" not in line and "\n" not in line and len(line) < 1000 for line in lines)


def test_the_sdk_log_limiter_says_the_summary_on_its_own_when_the_window_ends():
    lines: list[str] = []
    limiter = SdkLogLimiter(write=lines.append, window_s=0.2)
    limiter_records(limiter, [f"Client 127.0.0.1:5 attempted to subscribe to unknown channel: {i}" for i in range(50)])
    deadline = time.monotonic() + 5.0
    while len(lines) < 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert len(lines) == 2 and "49 more messages" in lines[1]
    limiter.close()
    assert len(lines) == 2


async def hostile_then_good_client(port: int) -> int:
    """Flood the server with faults from a few clients, then count the /cmd/gate messages a good client gets."""
    async def connect():
        deadline = time.monotonic() + 30.0
        while True:
            try:
                return await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"],
                                                max_size=None)
            except OSError:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.1)

    bad = await connect()
    await bad.send(json.dumps({"op": "subscribe",
                               "subscriptions": [{"id": i, "channelId": 100_000 + i} for i in range(5000)]}))
    for i in range(300):
        await bad.send("{not json" + str(i))
        await bad.send(json.dumps({"op": f"frob\x1b[2J{i}"}))
    others = [await connect() for _ in range(20)]
    for other in others:
        await other.send(json.dumps({"op": "unsubscribe", "subscriptionIds": list(range(100))}))
        await other.send("[]")
    for ws in [bad, *others]:
        await ws.close()
    async with await connect() as good:
        channels: dict = {}
        while "/cmd/gate" not in channels:
            op = json.loads(await asyncio.wait_for(good.recv(), 10.0))
            if op["op"] == "advertise":
                channels.update({c["topic"]: c for c in op["channels"]})
        await good.send(json.dumps({"op": "subscribe",
                                    "subscriptions": [{"id": 7, "channelId": channels["/cmd/gate"]["id"]}]}))
        count = 0
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            try:
                frame = await asyncio.wait_for(good.recv(), 0.5)
            except asyncio.TimeoutError:
                continue
            count += isinstance(frame, bytes) and frame[0] == 1
        return count


def test_hostile_clients_do_not_flood_the_terminal_and_the_run_goes_on(tmp_path):
    port = free_port()
    record = tmp_path / "live.mcap"
    run = subprocess.Popen([sys.executable, "-m", "beastbt", "run", str(REPO / "missions" / "patrol.yaml"),
                            "--speed", "realtime", "--max-time", "90 s", "--no-record", "--record", str(record),
                            "--foxglove", str(port)], cwd=tmp_path, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        gate_messages = asyncio.run(hostile_then_good_client(port))
    finally:
        run.send_signal(signal.SIGINT)  # the run outlives the clients however slow the machine; Ctrl-C ends it
        out, err = run.communicate(timeout=60)
    assert run.returncode == 1, err  # stopped by Ctrl-C, cleanly, as without the clients
    assert gate_messages > 20  # the server still serves (20 Hz for 2 s)
    said = [line for line in err.splitlines() if line.startswith("beastbt: foxglove:")]
    assert len(err.splitlines()) <= 8 and len(said) <= 7, err
    assert "\x1b" not in err
    assert any("5," in line and "more messages" in line for line in said), err  # the rest counted, said once
    assert read_recording(record).complete
