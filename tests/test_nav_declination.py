"""On the simulator the EKF takes the world's magnetic declination unless the profile sets one."""

from beastbt.testing import MissionHarness
from conftest import REPO


def test_ekf_uses_the_worlds_declination():
    h = MissionHarness.from_yaml("mission: t\nworld: campus.yaml\nsteps: [wait: 1 s]\n", base_dir=REPO / "worlds")
    assert h.run.estimator.ekf.config.declination_deg == 1.0
    assert h.run.estimator.ekf.config.use_magnetometer
