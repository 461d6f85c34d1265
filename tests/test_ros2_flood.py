"""A flood on the ROS 2 link's inputs does not stall the ticks: ``/cmd_vel`` is a stick (only its newest message
counts), and what else waits for the tick thread is bounded.

Found by the acceptance check of issue 35: a plain Zenoh peer putting ``/cmd_vel`` as fast as it could (about
400 000 messages a second on loopback) queued every message, and the tick that carried them out took about a
second (the odometry stopped for that long), so the robot drove on at full speed for 1.6 s after the last
message instead of the deadman's 0.5 s. A plain Zenoh peer on loopback puts the /cmd_vel flood; the bad messages
are handed to the link's own receiver (what Zenoh's thread does).
"""

from __future__ import annotations

import struct

import pytest

from beastbt.ros2 import cdr
from beastbt.testing import MissionHarness
from fleet_support import free_port, wait_for

pytest.importorskip("zenoh")

MISSION = """mission: stand_by
steps:
  - wait: 60 s
"""


class _Sample:
    """What a Zenoh sample gives the receiver: its payload."""

    def __init__(self, data: bytes) -> None:
        self.payload = self
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data


def _twist(linear: float) -> bytes:
    return cdr.HEADER_LE + struct.pack("<6d", linear, 0.0, 0.0, 0.0, 0.0, 0.0)


@pytest.fixture()
def harness():
    from beastbt.ros2.link import Ros2Link
    h = MissionHarness.from_yaml(MISSION, ros2={"listen": f"tcp/127.0.0.1:{free_port()}"})
    try:
        (link,) = [c.__self__ for c in h.prepared.closers if isinstance(getattr(c, "__self__", None), Ros2Link)]
        h.tick(2)
        yield h, link
    finally:
        h.prepared.abandon()


def test_a_cmd_vel_flood_is_one_command_a_tick_the_newest(harness):
    import json
    import time

    import zenoh

    from beastbt.live.console_control import AXIS_LINEAR
    from beastbt.ros2 import rmw_zenoh as rz
    h, link = harness
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([link.options.listen]))
    s = zenoh.open(conf)
    try:
        wait_for(lambda: [r for r in s.liveliness().get("@ros2_lv/**", timeout=1.0)
                          if r.ok is not None and "%cmd_vel/" in str(r.ok.key_expr)], 30, "the /cmd_vel subscription")
        # blocking, not dropping as Zenoh does by default when its queue is full: the last message must arrive
        pub = s.declare_publisher(rz.topic_key(0, "/cmd_vel", "geometry_msgs/msg/Twist"),
                                  congestion_control=zenoh.CongestionControl.BLOCK)
        for i in range(5000):  # no tick meanwhile: all of these come before the next one
            pub.put(_twist(0.001 * (i % 100)))
        pub.put(_twist(0.2))
        override = h.run.ctx.services.teleop
        scale = override.teleop.config.scale_linear_mps
        applied, ticks = link.controls.applied, 0

        def newest_carried_out() -> bool:
            nonlocal ticks
            h.tick()
            ticks += 1
            time.sleep(0.01)
            remote = override.remote
            return remote is not None and remote.axes[AXIS_LINEAR] == pytest.approx(min(1.0, 0.2 / scale))
        wait_for(newest_carried_out, 30, "the last /cmd_vel carried out")
        assert link.controls.applied - applied <= ticks  # at most one stick command a tick, not one a message
        assert link._pending.empty()
    finally:
        s.close()


def test_bad_messages_beyond_the_bound_are_dropped_and_counted(harness):
    from beastbt.ros2.link import MAX_PENDING
    h, link = harness
    receive = link._receiver("goal_pose")
    for _ in range(5000):
        receive(_Sample(b"\x00\x01\x00\x00junk"))
    assert link._pending.qsize() <= MAX_PENDING
    h.tick()
    texts = [e.text for e in h.events if e.kind == "ros2"]
    assert sum("not understood" in t for t in texts) <= MAX_PENDING
    assert any(t.startswith(f"{5000 - MAX_PENDING} ROS 2 messages dropped") for t in texts), texts[-3:]
