"""Replay is the same assembly as the run: the same parts install the same hooks, whatever the profile.

A run recorded on any robot profile (the shipped ones on the simulator, and
one whose ``navigation:``, ``control:`` and ``estimator:`` are tuned away
from their defaults) replays with no difference, tick for tick. Before replay
went through :func:`beastbt.assembly.assemble`, it skipped what parts install
before a run (the navigation tuning among them), and the tuned GPS route
replayed with almost every tick differing.
"""

from __future__ import annotations

import io
from pathlib import Path

import pytest
import yaml

from beastbt.assembly import prepare
from beastbt.recording.reader import read_recording
from beastbt.replay import replay
from beastbt.run.session import RunOptions, execute
from conftest import REPO

GPS_ROUTE = REPO / "missions" / "gps_route.yaml"
PATROL = REPO / "missions" / "patrol.yaml"

TUNING = {
    "navigation": {"lookahead_m": 0.9, "regulated_min_radius_m": 0.5, "min_speed_mps": 0.12,
                   "approach_dist_m": 1.6, "default_tolerance_m": 1.5, "rotate_to_heading_min_angle_rad": 0.6},
    "control": {"default_speed_mps": 0.25, "heading_gain": 3.0, "turn_gain": 2.0},
    "estimator": {"accel_noise_mps2": 1.2, "gps_gate_chi2": 30.0},
}
"""Knobs far enough from their defaults that the robot drives the route differently."""


def record(mission: Path, profile: str, runs: Path, max_time_s: float, seed: int = 4) -> tuple[Path, dict]:
    """Run ``mission`` on ``profile`` on the simulator, recorded; return the run folder and the summary."""
    p = prepare(str(mission), RunOptions(robot=profile, simulate=True, seed=seed, max_time_s=max_time_s,
                                         runs_dir=str(runs)))
    summary = execute(p, io.StringIO())
    assert p.folder is not None
    return p.folder.path, summary


def tuned_profile(tmp_path: Path) -> Path:
    """robots/sim.yaml with the TUNING sections merged in."""
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    for section, knobs in TUNING.items():
        data.setdefault(section, {}).update(knobs)
    data["robot"] = "tuned"
    path = tmp_path / "tuned.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def gate_commands(folder: Path) -> list[tuple[float, float]]:
    return [(m["linear_mps"], m["angular_rps"]) for m in read_recording(folder / "run.mcap").topic("/cmd/gate")]


def test_a_run_with_a_tuned_navigation_profile_replays_tick_for_tick(tmp_path):
    profile = tuned_profile(tmp_path)
    try:
        tuned, summary = record(GPS_ROUTE, str(profile), tmp_path / "runs", max_time_s=60.0)
    except Exception as exc:  # a knob the schema does not know would be a bug in this test
        pytest.fail(f"the tuned profile does not load: {exc}")
    default, _ = record(GPS_ROUTE, "sim", tmp_path / "default_runs", max_time_s=60.0)
    # The tuning matters: the same seed on the default profile drives differently.
    assert gate_commands(tuned) != gate_commands(default)
    result = replay(str(tuned))
    assert result.identical, [d.describe() for d in result.differences[:5]]
    assert result.ticks == summary["ticks"] and result.differing_ticks == 0


@pytest.mark.parametrize("profile", ["ugv_beast", "diy_can", "diy_pwm"])
def test_a_run_on_each_shipped_profile_replays_tick_for_tick(profile, tmp_path):
    folder, summary = record(PATROL, str(REPO / "robots" / f"{profile}.yaml"), tmp_path / "runs", max_time_s=25.0)
    assert summary["robot"] == profile and summary["ticks"] > 50
    result = replay(str(folder))
    assert result.identical, [d.describe() for d in result.differences[:5]]
    assert result.ticks == summary["ticks"]
