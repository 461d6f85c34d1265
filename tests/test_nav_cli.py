"""`beastbt gps decode`, and the robot/world schema parts of navigation: misspelt knobs rejected where they are."""

from __future__ import annotations

import json

import pytest

from beastbt import cli
from beastbt.core.errors import InvalidInput
from beastbt.robot.profile import load_profile
from beastbt.sim.world import load_world
from conftest import REPO

MT3339 = REPO / "tests" / "data" / "nmea" / "mt3339.log"


def test_gps_decode_prints_one_json_line_per_fix_and_a_summary(capsys):
    assert cli.main(["gps", "decode", str(MT3339)]) == 0
    out, err = capsys.readouterr()
    records = [json.loads(line) for line in out.splitlines()]
    assert len(records) == 60
    assert {r["sentence"] for r in records} == {"GGA", "RMC"}
    first_rmc = next(r for r in records if r["sentence"] == "RMC")
    assert first_rmc["time"] == "2015-04-13T20:26:40.000Z"
    assert first_rmc["lat"] == pytest.approx(44.068843333, abs=1e-9)
    assert first_rmc["speed_mps"] is not None and first_rmc["alt_msl"] is None
    gga = [r for r in records if r["sentence"] == "GGA"]
    assert all(r["alt_msl"] is not None and r["speed_mps"] is None for r in gga)
    assert err.count("\n") == 1 and "read 138 sentences" in err and "60 positions" in err


def test_gps_decode_of_a_missing_file_exits_2(capsys, tmp_path):
    assert cli.main(["gps", "decode", str(tmp_path / "nope.log")]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_gps_without_an_action_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["gps", "encode", str(MT3339)])
    assert e.value.code == 2
    assert "invalid choice" in capsys.readouterr().err


@pytest.mark.parametrize("section, good, bad, closest", [
    ("gps", "  port_baud: 9600", "  port_buad: 9600", "port_baud"),
    ("imu", "  dlpf: 3", "  dlfp: 3", "dlpf"),
    ("estimator", "  course_min_speed_mps: 0.15", "  course_min_speed: 0.15", "course_min_speed_mps"),
])
def test_a_misspelt_knob_in_the_sim_profile_is_rejected_at_its_line(tmp_path, section, good, bad, closest):
    text = (REPO / "robots" / "sim.yaml").read_text()
    assert good in text
    path = tmp_path / "robot.yaml"
    path.write_text(text.replace(good, bad, 1))
    line = next(i for i, t in enumerate(path.read_text().splitlines(), start=1) if t.startswith(bad))
    with pytest.raises(InvalidInput) as e:
        load_profile(str(path))
    text = e.value.format()
    assert f"robot.yaml:{line}:3: error: unknown key '{bad.split(':')[0].strip()}' in '{section}'" in text
    assert f"did you mean '{closest}'" in text


def test_a_misspelt_navigation_knob_is_rejected(tmp_path):
    path = tmp_path / "robot.yaml"
    path.write_text((REPO / "robots" / "sim.yaml").read_text() + "navigation:\n  lookahed_m: 2.0\n")
    with pytest.raises(InvalidInput) as e:
        load_profile(str(path))
    n = len(path.read_text().splitlines())
    assert f"robot.yaml:{n}:3: error: unknown key 'lookahed_m' in 'navigation'; did you mean 'lookahead_m'?" in e.value.format()


@pytest.mark.parametrize("good, bad, section, closest", [
    ("  white_sigma_m: 2.0", "  white_sigma: 2.0", "gps", "white_sigma_m"),
    ("  mag_declination_deg: 1.0", "  mag_declination: 1.0", "imu", "mag_declination_deg"),
])
def test_a_misspelt_knob_in_a_world_is_rejected_at_its_line(tmp_path, good, bad, section, closest):
    text = (REPO / "worlds" / "campus.yaml").read_text()
    assert good in text
    path = tmp_path / "w.yaml"
    path.write_text(text.replace(good, bad, 1))
    line = next(i for i, t in enumerate(path.read_text().splitlines(), start=1) if t.startswith(bad))
    with pytest.raises(InvalidInput) as e:
        load_world(path)
    assert f"w.yaml:{line}:3: error: unknown key '{bad.split(':')[0].strip()}' in '{section}'; did you mean '{closest}'?" \
        in e.value.format()


def test_a_world_gps_model_that_makes_no_sense_is_rejected_before_the_run(tmp_path):
    path = tmp_path / "w.yaml"
    path.write_text((REPO / "worlds" / "campus.yaml").read_text().replace(
        "  cold_start_s: 1.0 ", "  dropouts_s: [[20, 10]]\n  cold_start_s: 1.0 ", 1))
    mission = tmp_path / "m.yaml"
    mission.write_text("mission: t\nsteps:\n  - wait: 1 s\n")
    assert cli.main(["run", str(mission), "--world", str(path), "--no-record"]) == 2
