"""An ``/initialpose`` that decodes but makes no sense is not taken as given, and never ends the run.

Found by the acceptance check of issue 35: a PoseWithCovarianceStamped with an infinite (or a huge finite)
covariance, or at 1e300 m, spread the map localiser's particles nowhere and its next estimate divided by zero:
``beastbt run`` ended with "internal error: ZeroDivisionError". A pose off the map is now an event; the
spread is at most the map's size and half a turn. The link's own receiver is handed the bytes (what Zenoh's
thread does), without a network.
"""

from __future__ import annotations

import math
import struct

import pytest

from beastbt.ros2 import cdr
from beastbt.testing import MissionHarness
from conftest import REPO
from fleet_support import free_port

pytest.importorskip("zenoh")

MISSION = """mission: stand_on_the_map
world: ../worlds/office.yaml
map: ../maps/office.yaml
steps:
  - wait: 60 s
"""


class _Sample:
    def __init__(self, data: bytes) -> None:
        self.payload = self
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data


def _initial_pose(x: float, y: float, covariance: float) -> bytes:
    return (cdr.HEADER_LE + struct.pack("<iII", 0, 0, 4) + b"map\x00" + struct.pack("<7d", x, y, 0, 0, 0, 0, 1)
            + struct.pack("<36d", *([covariance] * 36)))


@pytest.mark.parametrize("x, y, covariance, said", [
    (1.0, 0.0, math.inf, "localising again"),
    (1e300, -1e300, 0.0, "not taken: it is off the map"),
])
def test_a_senseless_initial_pose_does_not_end_the_run(x, y, covariance, said):
    from beastbt.ros2.link import Ros2Link
    h = MissionHarness.from_yaml(MISSION, base_dir=REPO / "missions", ros2={"listen": f"tcp/127.0.0.1:{free_port()}"})
    try:
        (link,) = [c.__self__ for c in h.prepared.closers if isinstance(getattr(c, "__self__", None), Ros2Link)]
        h.tick(10)
        link._receiver("initialpose")(_Sample(_initial_pose(x, y, covariance)))
        h.tick(30)  # raised ZeroDivisionError from the localiser's estimate before
        pose = h.blackboard("map_pose")
        assert math.isfinite(pose.x) and math.isfinite(pose.y)
        texts = [e.text for e in h.events if e.kind == "ros2"]
        assert any(said in t for t in texts), texts
    finally:
        h.prepared.abandon()
