"""Hostile input files get a positioned refusal, exit 2 and no traceback, in bounded memory (issue 25, points 2, 3, 7).

Every case runs the public command line (``python -m beastbt validate FILE`` or ``run``) in a child process: alias
bombs in each kind of file (refused under an address-space limit of 1 GB, with the child's peak RSS measured),
huge and non-finite numbers where numbers go, and YAML reader errors that must point at their own line. Legitimate
anchors and aliases keep working. Timing is measured in benchmarks/input_limits.py, not here.
"""

from __future__ import annotations

import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO
from hostile_yaml import laughs, million_waits

ADDRESS_SPACE_LIMIT = 1 << 30
"""The bombs' children run under this RLIMIT_AS: an expanding bomb would die of MemoryError (a traceback) here."""
MAX_RSS_MB = 100


def beastbt(*args: str, cwd: Path) -> tuple[int, str, str]:
    """Run ``python -m beastbt ARGS``: (exit status, stdout, stderr)."""
    done = subprocess.run([sys.executable, "-m", "beastbt", *args], capture_output=True, text=True, timeout=120,
                          cwd=cwd, env=dict(os.environ, PYTHONPATH=str(REPO)))
    return done.returncode, done.stdout, done.stderr


_MEASURE = """
import os, resource, sys
limit, rss_file, args = int(sys.argv[1]), sys.argv[2], sys.argv[3:]
pid = os.fork()
if pid == 0:
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    os.execv(sys.executable, [sys.executable, "-m", "beastbt", *args])
_, status, usage = os.wait4(pid, 0)
with open(rss_file, "w") as f:
    f.write(str(usage.ru_maxrss))
sys.exit(os.waitstatus_to_exitcode(status))
"""
"""Runs beastbt from a small fresh Python: a child forked from pytest itself would count pytest's pages in its peak
RSS (Linux keeps the high-water mark across exec), so the measuring parent must be small."""


def beastbt_own_rss(*args: str, cwd: Path) -> tuple[int, str, str, float]:
    """Like :func:`beastbt`, under an address-space limit of :data:`ADDRESS_SPACE_LIMIT`, with the peak RSS of the
    beastbt process in MB (from ``os.wait4`` in a small parent)."""
    rss_file = cwd / "child.rss"
    done = subprocess.run([sys.executable, "-c", _MEASURE, str(ADDRESS_SPACE_LIMIT), str(rss_file), *args],
                          capture_output=True, text=True, timeout=120, cwd=cwd,
                          env=dict(os.environ, PYTHONPATH=str(REPO), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1"))
    return done.returncode, done.stdout, done.stderr, int(rss_file.read_text()) / 1024.0


BOMBS = {
    "mission, 9 levels": ("m.yaml", "mission: bomb\nsteps:\n  - wait: 1 s\n" + laughs(9)),
    "mission, 10 levels": ("m.yaml", "mission: bomb\nsteps:\n  - wait: 1 s\n" + laughs(10)),
    "mission, 6 levels": ("m.yaml", "mission: bomb\nsteps:\n  - wait: 1 s\n" + laughs(6)),
    "mission, 10^6 waits": ("m.yaml", million_waits()),
    "world": ("w.yaml", "world: bomb\ndescription: x\n" + laughs(9)),
    "robot profile": ("r.yaml", "robot: bomb\n" + laughs(9)),
    "joystick script": ("j.yaml", "- {at: 1 s, press: enable}\n" + "".join(
        f"- {{at: 2 s, press: enable, x: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10 if i else ["lol"] * 10) + "]}\n"
        for i in range(9))),
}


@pytest.mark.parametrize("name", list(BOMBS))
def test_an_alias_bomb_is_refused_at_its_alias_in_bounded_memory(tmp_path, name):
    file, text = BOMBS[name]
    path = tmp_path / file
    path.write_text(text)
    status, out, err, rss_mb = beastbt_own_rss("validate", str(path), cwd=tmp_path)
    assert status == 2, out + err
    assert "Traceback" not in err and "MemoryError" not in err
    found = re.search(rf"{re.escape(str(path))}:(\d+):(\d+): error: aliases expand this file to", err)
    assert found, err
    line = int(found.group(1))
    assert "*" in text.splitlines()[line - 1], f"not at an alias: {text.splitlines()[line - 1]!r}"
    assert "hint: aliases may add at most" in err
    assert rss_mb < MAX_RSS_MB, f"peak RSS {rss_mb:.0f} MB"


@pytest.mark.parametrize("option, file, text", [
    (None, "m.yaml", million_waits()),
    ("--world", "w.yaml", "world: bomb\n" + laughs(9)),
    ("--robot", "r.yaml", "robot: bomb\n" + laughs(9)),
    ("--joystick", "j.yaml", BOMBS["joystick script"][1]),
])
def test_run_refuses_a_bomb_in_any_of_its_files_before_anything_moves(tmp_path, option, file, text):
    path = tmp_path / file
    path.write_text(text)
    mission = tmp_path / "ok.yaml"
    mission.write_text("mission: ok\nsteps:\n  - wait: 1 s\n")
    args = ["run", str(path)] if option is None else ["run", str(mission), option, str(path)]
    status, out, err, rss_mb = beastbt_own_rss(*args, "--no-record", cwd=tmp_path)
    assert status == 2, out + err
    assert "Traceback" not in err and f"{path}:" in err and "aliases expand this file" in err
    assert "mission_end" not in out
    assert rss_mb < MAX_RSS_MB, f"peak RSS {rss_mb:.0f} MB"


def task_calls(levels: int, width: int) -> str:
    """Tasks that each run the one before ``width`` times, ``levels`` deep: ``width ** levels`` waits once the
    compiler copies each task in where ``do:`` runs it (no alias at all)."""
    text = "mission: calls\ntasks:\n  t0:\n" + "    - wait: 1 s\n" * width
    for i in range(1, levels):
        text += f"  t{i}:\n" + f"    - do: t{i - 1}\n" * width
    return text + f"steps:\n  - wait: 1 s\n  - do: t{levels - 1}\n"


@pytest.mark.parametrize("text, says", [
    (task_calls(6, 10), "more than 50,000 values in its tree"),
    (task_calls(1000, 1), "nests more than 100 levels"),
])
def test_tasks_that_would_compile_to_a_huge_or_too_deep_tree_are_refused_at_their_call(tmp_path, text, says):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    line = text.splitlines().index(text.splitlines()[-1]) + 1
    for command in ("validate", "run"):
        status, out, err, rss_mb = beastbt_own_rss(command, str(path), cwd=tmp_path)
        assert status == 2 and "Traceback" not in err, out + err
        assert f"{path}:{line}:9: error: with its tasks copied in wherever 'do:' runs them" in err and says in err
        assert rss_mb < MAX_RSS_MB, f"peak RSS {rss_mb:.0f} MB"


def test_tasks_calling_tasks_within_the_bounds_still_run(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text(task_calls(4, 5))  # 625 waits of 1 s
    status, out, err, _ = beastbt_own_rss("run", str(path), "--no-record", "--max-time", "3 s", cwd=tmp_path)
    assert status == 1 and "max time 3 s reached" in out, out + err


def test_an_alias_inside_its_own_anchor_is_refused(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("mission: loop\nsteps:\n  - wait: 1 s\nx: &a\n  - y: *a\n")
    status, _, err = beastbt("validate", str(path), cwd=tmp_path)
    assert status == 2 and "Traceback" not in err
    assert f"{path}:5:8: error: the alias *a is inside the anchor &a" in err


def test_legitimate_anchors_and_merge_keys_still_work(tmp_path):
    many = "".join(f"  - drive: {{<<: *slow, distance: {i % 3 + 1} m}}\n" for i in range(200))
    mission = tmp_path / "m.yaml"
    mission.write_text("mission: anchors\ntasks:\n  look: &look\n    - look: {pan: -45 deg}\n"
                       "    - look: {pan: 45 deg}\n  look_again: *look\n"
                       "steps:\n  - drive: &slow {distance: 1 m, speed: 0.1 m/s}\n"
                       f"{many}  - do: look_again\n")
    world = tmp_path / "w.yaml"
    world.write_text("world: walls\nwalls:\n" + "".join(f"  - &w{i} [0, {i}, 10, {i}]\n" for i in range(50))
                     + "".join(f"  - *w{i % 50}\n" for i in range(500)))
    script = tmp_path / "j.yaml"
    script.write_text("- &go {at: 1 s, linear: 0.5}\n- {<<: *go, at: 2 s}\n- {<<: *go, at: 3 s, linear: 0}\n")
    status, out, err = beastbt("validate", str(mission), str(world), str(script), cwd=tmp_path)
    assert status == 0, err
    assert out.count(": ok") == 3
    status, out, err = beastbt("run", str(mission), "--no-record", "--max-time", "1 s", cwd=tmp_path)
    assert status == 1 and "Traceback" not in err and "top speed 0.10 m/s" in out, err  # the anchored speed


def test_an_anchor_reused_within_the_bound_is_kept_whole(tmp_path):
    """1,000 uses of a 9-value mapping (9,000 values added) stay within the bound, and each use is the whole."""
    world = tmp_path / "w.yaml"
    world.write_text("world: reuse\nbattery: &b {start_v: 12.0, drain_v_per_s: 0.001}\n"
                     "walls:\n" + "".join("  - [0, 1, 2, 3]\n" for _ in range(10))
                     + "x_reuse:\n" + "".join(f"  k{i}: *b\n" for i in range(1000)))
    status, _, err = beastbt("validate", str(world), cwd=tmp_path)
    assert status == 2 and "aliases expand" not in err  # refused for its unknown key x_reuse, not as a bomb
    assert "unknown key 'x_reuse'" in err


# -- numbers ---------------------------------------------------------------------------------------------------

PLACES = "mission: n\nplaces:\n  a: {lat: 40.4168, lon: -3.7038}\nsteps:\n"
DIGITS_400, DIGITS_5000 = "9" * 400, "9" * 5000


MISSION_NUMBERS = [
    ("mission: n\nplaces:\n  a: {lat: .nan, lon: -3.7038}\nsteps:\n  - go_to: a\n", "3:12", "'lat'"),
    ("mission: n\nplaces:\n  a: {lat: 40.0, lon: -.inf}\nsteps:\n  - go_to: a\n", "3:23", "'lon'"),
    (f"mission: n\nplaces:\n  a: {{lat: {DIGITS_400}, lon: 1}}\nsteps:\n  - go_to: a\n", "3:12", "'lat'"),
    (PLACES + "  - go_to: {lat: 1.0e400, lon: 1.0}\n", "5:18", "'lat'"),
    (PLACES + "  - turn: {angle: -inf deg}\n", "5:19", "'angle'"),
    (PLACES + "  - turn: {angle: 36001 deg}\n", "5:19", "3600 deg"),
    (PLACES + "  - look: {pan: 1e308 deg}\n", "5:17", "'pan'"),
    (PLACES + "  - look: {pan: 400 deg}\n", "5:17", "from -360 deg to 360 deg"),
    (PLACES + "  - wait: " + "9" * 96 + "\n", "5:11", "'wait'"),
    (PLACES + "  - wait: " + "9" * 96 + " s\n", "5:11", "a week"),
    (PLACES + "  - wait: 1e400 s\n", "5:11", "finite"),
    (PLACES + "  - wait: 1e400\n", "5:11", "finite"),
    (PLACES + "  - wait: 200 h\n", "5:11", "a week"),
    (PLACES + "  - repeat: {times: 0x7fffffffffffffff, steps: [wait: 1 s]}\n", "5:21", "1000000"),
    (PLACES + "  - repeat: {times: 2000000, steps: [wait: 1 s]}\n", "5:21", "1000000"),
    (PLACES + "  - drive: {distance: 1e12 m}\n", "5:23", "1000 km"),
    (PLACES + f"  - drive: {{distance: 1 m, speed: {DIGITS_5000}}}\n", "5:35", "'speed'"),
    (PLACES + "  - drive: {distance: 1 m, speed: 1e9 km/h}\n", "5:35", "50 m/s"),
    (PLACES + "  - wait_until: {near: a, within: .inf}\n", "5:35", "'within'"),
    ("mission: n\nlimits: {acceleration: 1e400 m/s2}\nsteps:\n  - wait: 1 s\n", "2:24", "acceleration"),
    ("mission: n\nrate: 1e400 Hz\nsteps:\n  - wait: 1 s\n", "2:7", "finite"),
]
"""(mission text, line:column of the error, what its message says)."""


def test_a_mission_number_out_of_its_range_is_refused_where_it_is(tmp_path):
    paths = []
    for i, (text, _, _) in enumerate(MISSION_NUMBERS):
        paths.append(tmp_path / f"m{i}.yaml")
        paths[-1].write_text(text)
    status, out, err = beastbt("validate", *map(str, paths), cwd=tmp_path)  # one process for all: fast
    assert status == 2 and "Traceback" not in err and ": ok" not in out, out
    reports = {str(path): "" for path in paths}
    for report in re.split(r"\n(?=\S)", err):
        reports[report.split(":", 1)[0]] += report
    for path, (_, where, says) in zip(paths, MISSION_NUMBERS):
        report = reports[str(path)]
        assert report.startswith(f"{path}:{where}: error: ") and says in report, (path.read_text()[:300], report)
        assert "hint:" in report, report


@pytest.mark.parametrize("option, file, text, where", [
    ("--world", "w.yaml", f"world: w\nstart: {{x: {DIGITS_400}, y: 0}}\n", "2:12"),
    ("--world", "w.yaml", f"world: w\nwalls:\n  - [0, 0, {DIGITS_5000}, 1]\n", "3:12"),
    ("--world", "w.yaml", "world: w\ndatum: {lat: .nan, lon: 1.0}\n", "2:14"),
    ("--world", "w.yaml", "world: w\nwalls:\n  - [0, 0, 1.0e300, 1]\n", "3:12"),
    ("--world", "w.yaml", "world: w\ngps: {white_sigma_m: 1.0e12}\n", "2:22"),
    ("--robot", "r.yaml", "robot: r\nlimits: {max_speed_mps: .inf}\n", "2:25"),
    ("--robot", "r.yaml", f"robot: r\nlimits: {{max_accel_mps2: {DIGITS_400}}}\n", "2:26"),
    ("--robot", "r.yaml", "robot: r\ngeometry: {track_width_m: 1e400 m}\n", "2:27"),
    ("--joystick", "j.yaml", f"- {{at: 1 s, press: enable}}\n- {{at: 2 s, linear: {DIGITS_400}}}\n", "2:21"),
    ("--joystick", "j.yaml", f"- {{at: 1 s, press: enable}}\n- {{at: {DIGITS_5000}, linear: 0.5}}\n", "2:8"),
    ("--joystick", "j.yaml", "- {at: 1 s, press: enable}\n- {at: 2 s, linear: .nan}\n", "2:21"),
    ("--joystick", "j.yaml", "- {at: 1 s, press: enable}\n- {at: " + "9" * 96 + " s, linear: 0.5}\n", "2:8"),
])
def test_huge_and_non_finite_numbers_in_worlds_profiles_and_scripts_are_refused(tmp_path, option, file, text, where):
    path = tmp_path / file
    path.write_text(text)
    mission = tmp_path / "ok.yaml"
    mission.write_text("mission: ok\nsteps:\n  - wait: 1 s\n")
    runs = [["validate", str(path)]]
    if DIGITS_400 in text:  # and run, once for each kind of file (a run costs seconds)
        runs.append(["run", str(mission), option, str(path), "--no-record"])
    for args in runs:
        status, out, err = beastbt(*args, cwd=tmp_path)
        assert status == 2, out + err
        assert "Traceback" not in err and "OverflowError" not in err
        assert f"{path}:{where}: error: " in err, err
        assert "mission_end" not in out


def test_a_refused_number_names_the_range_of_its_field(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("mission: n\nplaces:\n  a: {lat: .nan, lon: -3.7038}\nsteps:\n  - go_to: a\n")
    _, _, err = beastbt("validate", str(path), cwd=tmp_path)
    assert "'lat' is a number from -90 to 90" in err


# -- where the YAML reader stops ----------------------------------------------------------------------------------

PATROL_LINES = (REPO / "missions" / "patrol.yaml").read_text().splitlines()


READER_ERRORS = [
    ("control character", lambda line: line + "\x01", None),
    ("NUL", lambda line: line + "\x00", None),
    ("tab", lambda line: "\t" + line, 1),
    ("bad escape", lambda line: line.replace("2 s", '"2\\q s"'), None),
    ("escape beyond Unicode", lambda line: line.replace("2 s", '"\\U0011FFFF"'), None),
    ("unclosed quote", lambda line: line.replace("2 s", '"2 s'), 13),
    ("bad !!int", lambda line: line.replace("2 s", "!!int 2 s"), 13),
    ("bad date", lambda line: line.replace("2 s", "2024-13-45"), 13),
    ("bad !!bool", lambda line: line.replace("2 s", "!!bool maybe"), 13),
    ("bad !!timestamp", lambda line: line.replace("2 s", "!!timestamp x"), 13),
    ("an anchor without a name", lambda line: line.replace("2 s", "&"), None),
]
"""(what is wrong, how line 9 of patrol.yaml is changed, the column of the error when it is exact)."""


def test_a_yaml_reader_error_on_line_9_is_reported_on_line_9(tmp_path):
    paths = []
    for i, (_, mutate, _) in enumerate(READER_ERRORS):
        lines = list(PATROL_LINES)
        assert lines[8].strip() == "- wait: 2 s"
        lines[8] = mutate(lines[8])
        paths.append(tmp_path / f"m{i}.yaml")
        paths[-1].write_text("\n".join(lines) + "\n")
    status, _, err = beastbt("validate", *map(str, paths), cwd=tmp_path)
    assert status == 2 and "Traceback" not in err
    for path, (name, _, column) in zip(paths, READER_ERRORS):
        found = re.search(rf"{re.escape(str(path))}:(\d+):(\d+): error: ", err)
        assert found and found.group(1) == "9", (name, err)
        if column is not None:
            assert found.group(2) == str(column), (name, err)


def test_bytes_that_are_not_utf8_are_reported_at_their_line(tmp_path):
    lines = [line.encode() for line in PATROL_LINES]
    lines[9] += b" \xff"
    path = tmp_path / "m.yaml"
    path.write_bytes(b"\n".join(lines) + b"\n")
    status, _, err = beastbt("validate", str(path), cwd=tmp_path)
    assert status == 2 and "Traceback" not in err
    assert f"{path}:10:{len(PATROL_LINES[9]) + 2}: error: byte 0xff" in err
