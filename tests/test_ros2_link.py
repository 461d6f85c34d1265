"""The ROS 2 link end to end, without ROS: a plain Zenoh peer on loopback plays the ROS 2 laptop.

One simulated run (``beastbt run ... --speed realtime --ros2 tcp/127.0.0.1:PORT``, recorded) is watched
and driven by a Zenoh peer that subscribes to ``**`` and reads the liveliness tokens, as rmw_zenoh's graph
cache does; it publishes ``/cmd_vel`` (Twist, then TwistStamped) on rmw_zenoh's keys with rmw_zenoh's
attachment, then falls silent, then sends ``/estop``. What it saw is decoded by rosbags' Humble and Jazzy
type stores; what the robot did is read from the run's recording.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from beastbt.ros2 import cdr, rmw_zenoh as rz
from conftest import REPO
from fleet_support import free_port, wait_for

zenoh = pytest.importorskip("zenoh")
typesys = pytest.importorskip("rosbags.typesys")

MISSION = """mission: stand_by
steps:
  - wait: 60 s
"""


def peer(port: int):
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("timestamping/enabled", "true")
    return zenoh.open(conf)


def twist_bytes(store, lin: float, ang: float, stamped: bool) -> bytes:
    g = "geometry_msgs/msg/"
    t = store.types
    twist = t[g + "Twist"](linear=t[g + "Vector3"](x=lin, y=0.0, z=0.0), angular=t[g + "Vector3"](x=0.0, y=0.0, z=ang))
    if not stamped:
        return bytes(store.serialize_cdr(twist, g + "Twist"))
    header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="base_link")
    return bytes(store.serialize_cdr(t[g + "TwistStamped"](header=header, twist=twist), g + "TwistStamped"))


@pytest.fixture(scope="module")
def session_run(tmp_path_factory):
    """Run the scenario once: watch, drive for 2 s, fall silent, e-stop. Returns what was seen and recorded."""
    tmp = tmp_path_factory.mktemp("ros2")
    mission = tmp / "stand_by.yaml"
    mission.write_text(MISSION)
    port = free_port()
    record = tmp / "run.mcap"
    summary = tmp / "summary.json"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt", "run", str(mission), "--speed", "realtime",
                             "--max-time", "60 s", "--no-record", "--record", str(record), "--summary", str(summary),
                             "--ros2", f"tcp/127.0.0.1:{port}"], cwd=tmp, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen: list[tuple[str, bytes, bytes]] = []
    lock = threading.Lock()
    jazzy = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    s = None
    try:
        s = wait_for(lambda: _try_peer(port), 60, "the run's ROS 2 link to listen")

        def take(sample) -> None:
            att = sample.attachment.to_bytes() if sample.attachment is not None else b""
            with lock:
                seen.append((str(sample.key_expr), sample.payload.to_bytes(), att))
        sub = s.declare_subscriber("**", take)
        # The link declares its tokens one by one (the node, each publisher, then each subscription), as a ROS 2
        # node's graph fills in: under load a first look may come half way. Waited for until /cmd_vel's two
        # subscriptions, declared after every publisher, are there (the test below checks them all).
        tokens = wait_for(lambda: (lambda t: t if any("/MS/" in k and "TwistStamped_" in k for k in t) else None)(
            _tokens(s)), 30, "the liveliness tokens up to /cmd_vel's subscriptions")
        import zenoh.ext
        latched: list[bytes] = []
        tf_static = rz.topic_key(0, "/tf_static", "tf2_msgs/msg/TFMessage")
        late = zenoh.ext.declare_advanced_subscriber(
            s, tf_static, lambda sample: latched.append(sample.payload.to_bytes()),
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True))
        wait_for(lambda: any(k.startswith("0/scan/") for k, _, _ in list(seen)), 30, "a /scan")
        # Drive: Twist for 1 s, then TwistStamped for 1 s, at 10 Hz, with rmw_zenoh's attachment.
        gid = rz.gid("@ros2_lv/0/test/0/1/MP/%/%/teleop/%cmd_vel/x/y/::,10:,:,:,,")
        seq = 0
        for stamped in (False, True):
            key = rz.topic_key(0, "/cmd_vel", "geometry_msgs/msg/TwistStamped" if stamped
                               else "geometry_msgs/msg/Twist")
            pub = s.declare_publisher(key)
            for _ in range(10):
                seq += 1
                pub.put(twist_bytes(jazzy, 0.2, 0.0, stamped), attachment=rz.attachment(seq, time.time_ns(), gid))
                time.sleep(0.1)
            pub.undeclare()
        last_put_ns = time.time_ns()
        time.sleep(1.5)  # silent: the deadman lets go within 0.5 s
        estop = s.declare_publisher(rz.topic_key(0, "/estop", "std_msgs/msg/Bool"))
        estop.put(cdr.encode_bool(True), attachment=rz.attachment(1, time.time_ns(), gid))
        out = proc.communicate(timeout=60)[0]
        late.undeclare()
        sub.undeclare()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        if s is not None:
            s.close()
    from beastbt.recording.reader import read_recording
    rec = read_recording(record, topics=["/operator/input", "/cmd/gate"])
    return {"seen": seen, "tokens": tokens, "out": out, "code": proc.returncode, "latched": latched,
            "last_put_ns": last_put_ns, "record": record,
            "summary": json.loads(summary.read_text()), "rec": rec}


def _try_peer(port: int):
    try:
        s = peer(port)
    except Exception:  # noqa: BLE001 - not listening yet
        return None
    if not list(s.liveliness().get("@ros2_lv/**", timeout=1.0)):
        s.close()
        return None
    return s


def _tokens(s) -> list[str]:
    return [str(r.ok.key_expr) for r in s.liveliness().get("@ros2_lv/**", timeout=2.0) if r.ok is not None]


TOPIC_TYPES = {"odom": "nav_msgs/msg/Odometry", "tf": "tf2_msgs/msg/TFMessage", "scan": "sensor_msgs/msg/LaserScan",
               "imu/data": "sensor_msgs/msg/Imu", "battery": "sensor_msgs/msg/BatteryState",
               "diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}


def test_a_plain_zenoh_peer_sees_the_topics_on_rmw_zenohs_keys(session_run):
    keys = {k for k, _, _ in session_run["seen"]}
    for topic, typ in TOPIC_TYPES.items():
        assert rz.topic_key(0, "/" + topic, typ) in keys, (topic, sorted(keys))


@pytest.mark.parametrize("store_name", ["ROS2_HUMBLE", "ROS2_JAZZY"])
def test_every_message_decodes_with_rosbags(session_run, store_name):
    store = typesys.get_typestore(getattr(typesys.Stores, store_name))
    by_dds = {cdr.TYPES[t].dds_name: t for t in cdr.TYPES}
    n = 0
    for key, payload, _ in session_run["seen"]:
        parts = key.split("/")
        if parts[-2] not in by_dds or key.startswith("0/cmd_vel") or key.startswith("0/estop"):
            continue
        msg = store.deserialize_cdr(payload, by_dds[parts[-2]])
        n += 1
        if parts[1] == "scan":
            assert msg.header.frame_id == "lidar" and len(msg.ranges) > 100
            assert msg.range_max == pytest.approx(12.0) and abs(msg.angle_increment) > 0
        elif parts[1] == "odom":
            assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
            assert msg.pose.pose.orientation.w ** 2 + msg.pose.pose.orientation.z ** 2 == pytest.approx(1.0)
        elif parts[1] == "tf":
            assert [t.child_frame_id for t in msg.transforms] == ["odom", "base_link"]
    assert n > 50


def test_the_robot_moved_as_odom_says(session_run):
    jazzy = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    key = rz.topic_key(0, "/odom", "nav_msgs/msg/Odometry")
    xs = [jazzy.deserialize_cdr(p, "nav_msgs/msg/Odometry").pose.pose.position.x
          for k, p, _ in session_run["seen"] if k == key]
    # the run's own distance (summary) is what /odom showed: the sim robot starts facing east (x) in the empty world
    assert max(xs) - min(xs) == pytest.approx(session_run["summary"]["distance_m"], abs=0.08)
    assert session_run["summary"]["distance_m"] > 0.15


def test_attachments_are_rmw_zenohs(session_run):
    by_key: dict[str, list] = {}
    for key, _, att in session_run["seen"]:
        if key.startswith("0/cmd_vel") or key.startswith("0/estop"):
            continue
        by_key.setdefault(key, []).append(rz.parse_attachment(att))
    for key, atts in by_key.items():
        seqs = [a[0] for a in atts]
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs), key
        assert len({a[2] for a in atts}) == 1, key  # one GID per publisher
        assert all(abs(a[1] - time.time_ns()) < 600e9 for a in atts)  # Unix ns, this run


def test_liveliness_tokens_announce_node_publishers_and_subscriptions(session_run):
    tokens = session_run["tokens"]
    nodes = [t for t in tokens if "/NN/" in t]
    assert len(nodes) == 1 and nodes[0].endswith("/NN/%/%/beastbt")
    zid = nodes[0].split("/")[2]
    node = rz.Node(0, zid, 0)
    scan = [t for t in tokens if "/MP/" in t and "%scan/" in t]
    assert len(scan) == 1
    eid = int(scan[0].split("/")[4])
    assert scan[0] == node.endpoint_token(eid, rz.PUBLISHER, "/scan", "sensor_msgs/msg/LaserScan", rz.SENSOR_DATA)
    assert any("/MS/" in t and "%cmd_vel/geometry_msgs::msg::dds_::Twist_/" in t for t in tokens)
    assert any("/MS/" in t and "%cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/" in t for t in tokens)


def test_tf_static_is_transient_local(session_run):
    # the peer subscribed after the link had put /tf_static: it came from the publisher's cache
    assert session_run["latched"], "no /tf_static for a late subscriber"
    jazzy = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    msg = jazzy.deserialize_cdr(session_run["latched"][0], "tf2_msgs/msg/TFMessage")
    lidar = [t for t in msg.transforms if t.child_frame_id == "lidar"]
    assert lidar and lidar[0].transform.translation.z == pytest.approx(0.12)  # robots/sim.yaml lidar mounting


def test_cmd_vel_drives_as_teleop_and_the_deadman_lets_go(session_run):
    inputs = [m for _, m in session_run["rec"].messages.get("/operator/input", [])]
    teleop = [m for m in inputs if m["control"] == "teleop"]
    silent = [m for m in inputs if m["control"] == "stick_silent"]
    assert len(teleop) >= 15 and silent, inputs[-5:]
    last_s, stop_s = teleop[-1]["now_s"], silent[0]["now_s"]
    assert stop_s > last_s
    gates = [m for _, m in session_run["rec"].messages["/cmd/gate"]]
    driven = [g for g in gates if last_s - 0.5 <= g["now_s"] <= last_s]
    assert driven and all(g["mux_source"] == "teleop" for g in driven)
    assert max(g["linear_mps"] for g in driven) == pytest.approx(0.2, abs=0.03)  # 0.2 m/s asked, within the scale
    after = [g for g in gates if g["now_s"] > stop_s + 1e-6]
    assert after and all(g["linear_mps"] == 0.0 for g in after)  # released at once, not ramped down


def test_the_robot_stops_within_half_a_second_of_the_last_cmd_vel(session_run):
    # Wall time, as the laptop sees it: the put time of each /odom (its attachment's source timestamp) against
    # the put time of the last /cmd_vel. The deadman is 0.5 s; a tick, the motors' lag and a loaded machine's
    # scheduling come on top, so the bound here is generous (the exact figure is the deadman's, above).
    jazzy = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    key = rz.topic_key(0, "/odom", "nav_msgs/msg/Odometry")
    odom = [(rz.parse_attachment(a)[1], jazzy.deserialize_cdr(p, "nav_msgs/msg/Odometry").twist.twist.linear.x)
            for k, p, a in session_run["seen"] if k == key]
    last = session_run["last_put_ns"]
    assert any(v > 0.15 for t, v in odom if t < last)  # it was driving
    moving_after = [t for t, v in odom if t > last and abs(v) > 0.01]
    stopped_by = (max(moving_after) if moving_after else last) - last
    assert stopped_by < 1.0e9, f"still moving {stopped_by / 1e9:.2f} s after the last /cmd_vel"


def test_estop_topic_stops_the_run(session_run):
    assert session_run["code"] == 1
    assert session_run["summary"]["status"] == "stopped"
    assert any("ROS 2 /estop" in e["text"] for e in session_run["summary"]["events"])



def test_a_run_driven_from_ros2_replays_identically_up_to_the_estop(session_run):
    # /cmd_vel went through the console's controls: the recording notes each with its tick, so the replay
    # carries them out again at the same ticks, and the deadman's release too. The e-stop is not an operator
    # input: beastbt replay re-applies only the console's own e-stop (as for the fleet's), so the last tick,
    # the one the /estop latched in, is the one difference.
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-m", "beastbt", "replay", str(session_run["record"])], env=env,
                       capture_output=True, text=True, timeout=600)
    assert "commands differ at 1 of" in r.stdout, r.stdout[-1500:] + r.stderr[-1500:]
    assert "mux: recorded 0.0000 m/s 0.0000 rad/s (estop, mux estop)" in r.stdout
