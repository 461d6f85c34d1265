"""``--ros2`` on the command line and the ``ros2:`` profile section: mistakes answered before anything moves."""

from __future__ import annotations

import os
import socket
import subprocess
import sys

from conftest import REPO


def beastbt(*args: str, cwd) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "beastbt", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)


def test_a_port_in_use_is_refused_with_a_hint(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        r = beastbt("run", str(REPO / "missions" / "patrol.yaml"), "--no-record", "--max-time", "1 s",
                    "--ros2", f"tcp/127.0.0.1:{port}", cwd=tmp_path)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "the ROS 2 link cannot open" in r.stderr and "hint:" in r.stderr and "Traceback" not in r.stderr


def test_a_bad_endpoint_and_a_missing_config_are_refused(tmp_path):
    r = beastbt("run", str(REPO / "missions" / "patrol.yaml"), "--ros2", "ftp/robot", cwd=tmp_path)
    assert r.returncode == 2 and "--ros2 takes a Zenoh endpoint" in r.stderr
    r = beastbt("run", str(REPO / "missions" / "patrol.yaml"), "--ros2", "--ros2-config", "nope.json5",
                cwd=tmp_path)
    assert r.returncode == 2 and "--ros2-config nope.json5: no such file" in r.stderr


def test_a_bad_ros2_section_is_an_error_at_its_line(tmp_path):
    profile = tmp_path / "robot.yaml"
    text = (REPO / "robots" / "sim.yaml").read_text()
    profile.write_text(text + "\nros2:\n  format: dds\n")
    line = len(text.splitlines()) + 3
    r = beastbt("validate", str(profile), cwd=tmp_path)
    assert r.returncode == 2 and f"robot.yaml:{line}:" in r.stderr and "format" in r.stderr, r.stderr
    profile.write_text(text + "\nros2:\n  format: bridge\n  namespace: /robot1\n  topics: [odom, scan]\n")
    assert beastbt("validate", str(profile), cwd=tmp_path).returncode == 0


def test_a_bare_ros2_listens_where_the_profile_says(tmp_path):
    import json

    from fleet_support import free_port
    port = free_port()
    profile = tmp_path / "robot.yaml"
    profile.write_text((REPO / "robots" / "sim.yaml").read_text() + f"\nros2:\n  listen: tcp/127.0.0.1:{port}\n")
    r = beastbt("run", str(REPO / "missions" / "patrol.yaml"), "--robot", str(profile), "--sim", "--no-record",
                "--max-time", "1 s", "--summary", "s.json", "--ros2", cwd=tmp_path)
    assert r.returncode == 1, r.stderr  # stopped at --max-time
    events = [e["text"] for e in json.loads((tmp_path / "s.json").read_text())["events"] if e["kind"] == "ros2"]
    assert events and f"on tcp/127.0.0.1:{port}: takes /cmd_vel" in events[0]
