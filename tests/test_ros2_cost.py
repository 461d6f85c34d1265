"""What keeps the ROS 2 link cheap (benchmarks/ros2_cpu.py measures it): bursts, and nothing made for no one.

* The ticks' messages are made and sent together at most every 0.1 s (``BURST_PERIOD_S``): one wake-up of
  Zenoh's transmission per burst, each message still at its own rate with its own tick's stamp.
* A topic no subscriber matches (Zenoh's matching status, kept by the link) is neither encoded nor sent.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from beastbt.blackboard.types import FusedPose, ImuSample, LaserScan, VelocityCommand
from beastbt.ros2 import topics as topics_module
from beastbt.ros2.topics import BURST_PERIOD_S, RunTopics
from beastbt.run.runner import TickRecord

TICK_S = 0.05
"""The patrol's 20 Hz."""


def _topics(out: list, wanted=lambda name: True) -> RunTopics:
    from beastbt.robot.profile import load_profile
    run = SimpleNamespace(ctx=SimpleNamespace(services=SimpleNamespace(plugins={})))
    return RunTopics(run, load_profile("sim"), frozenset({"odom", "tf", "scan", "imu"}),
                     lambda name, payload: out.append((name, payload)), 0.0, wanted)


def _ticks(topics: RunTopics, out: list, n: int) -> list[list[str]]:
    """Tick ``n`` times at 20 Hz (a scan every other tick, an IMU sample each, the robot driving); the names sent
    at each tick."""
    sent_at = []
    angles = np.linspace(-math.pi, math.pi, 90, endpoint=False)
    zero = VelocityCommand()
    for i in range(n):
        t = i * TICK_S
        readings = [ImuSample(t, (0.0, 0.0, 0.1), (0.0, 0.0, 9.81))]
        if i % 2 == 0:
            readings.insert(0, LaserScan(t, angles, np.full(90, 2.0), np.full(90, 100.0), 10.0, "ld19"))
        pose = FusedPose(t, 0.2 * t, 0.0, 0.0, speed_mps=0.2)
        before = len(out)
        topics.on_tick(TickRecord(i, t, readings, pose, pose, zero, zero, zero, "mission", []))
        sent_at.append([name for name, _ in out[before:]])
    return sent_at


def test_messages_go_in_bursts_at_most_every_tenth_of_a_second_each_with_its_ticks_stamp():
    typesys = pytest.importorskip("rosbags.typesys")
    out: list = []
    sent_at = _ticks(_topics(out), out, 20)
    bursts = [i for i, names in enumerate(sent_at) if names]
    assert BURST_PERIOD_S == pytest.approx(0.1)
    assert bursts == list(range(0, 20, 2))  # every other 20 Hz tick: 10 wake-ups a second, not 20
    # ... yet every tick's pose and IMU sample went, at their own rates (20 Hz here), in order, stamped when measured
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    odom = [store.deserialize_cdr(p, "nav_msgs/msg/Odometry") for n, p in out if n == "odom"]
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in odom]
    assert stamps == pytest.approx([i * TICK_S for i in range(19)], abs=1e-6)  # the 20th waits for its burst
    assert [m.pose.pose.position.x for m in odom] == pytest.approx([0.2 * i * TICK_S for i in range(19)])
    assert sum(n == "imu" for n, _ in out) == 19 and sum(n == "scan" for n, _ in out) == 10


def test_a_topic_no_one_subscribes_to_is_not_even_encoded(monkeypatch):
    def no_scan_for_no_one(*args, **kwargs):
        raise AssertionError("a /scan was encoded for no subscriber")
    monkeypatch.setattr(topics_module, "scan_message", no_scan_for_no_one)
    out: list = []
    topics = _topics(out, wanted=lambda name: name != "scan")
    _ticks(topics, out, 6)
    names = {name for name, _ in out}
    assert "scan" not in names and {"odom", "tf", "imu"} <= names


def test_the_link_follows_zenohs_matching_status():
    """A publisher's status, as the link keeps it: False until a subscriber matches, True then, False after."""
    zenoh = pytest.importorskip("zenoh")
    import time

    from beastbt.ros2.link import Ros2Link, Ros2Options, session_config
    link = Ros2Link(SimpleNamespace(run=None), Ros2Options(listen=None))
    a = zenoh.open(session_config(Ros2Options(listen=None)))
    try:
        pub = a.declare_publisher("0/scan/sensor_msgs::msg::dds_::LaserScan_/x")
        link._watch_matching("scan", pub)
        assert link.wanted("scan") is False and link.wanted("odom") is True  # odom: not watched, always made
        sub = a.declare_subscriber("0/scan/**", lambda sample: None)  # a subscriber in the same session matches
        deadline = time.monotonic() + 10
        while not link.wanted("scan") and time.monotonic() < deadline:
            time.sleep(0.01)
        assert link.wanted("scan") is True
        sub.undeclare()
        deadline = time.monotonic() + 10
        while link.wanted("scan") and time.monotonic() < deadline:
            time.sleep(0.01)
        assert link.wanted("scan") is False
    finally:
        for item in link._subs:
            item.undeclare()
        a.close()
