"""On the simulator the EKF takes the world's magnetic declination unless the profile sets one."""

from beastbt.testing import MissionHarness
from conftest import REPO


def test_ekf_uses_the_worlds_declination():
    # A turn to a compass heading reads the fused pose, so the EKF is awake (it sleeps when nothing reads it).
    h = MissionHarness.from_yaml("mission: t\nworld: campus.yaml\nsteps: [turn: {heading: 90 deg}]\n", base_dir=REPO / "worlds")
    assert h.run.estimator.ekf.config.declination_deg == 1.0
    assert h.run.estimator.ekf.config.use_magnetometer
