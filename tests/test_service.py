"""``beastbt service``: the unit it writes passes ``systemd-analyze verify``, its ExecStart speaks systemd's notify
protocol (ready, a watchdog keep-alive every tick) to a fake NOTIFY_SOCKET, and a stalled loop stops feeding it."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conftest import REPO

PATROL = REPO / "missions" / "patrol.yaml"
NEEDS_SYSTEMD = pytest.mark.skipif(shutil.which("systemd-analyze") is None and not os.environ.get("CI"),
                                   reason="systemd-analyze is not installed (CI installs it)")


def beastbt(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "beastbt", *args], capture_output=True, text=True, timeout=120,
                          cwd=cwd, env=dict(os.environ, PYTHONPATH=str(REPO)))


def install(tmp_path: Path, *args: str) -> str:
    done = beastbt("service", "install", "--root", str(tmp_path / "root"), *args, cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    return (tmp_path / "root" / "etc" / "systemd" / "system" / "beastbt.service").read_text(encoding="utf-8")


def unit_values(text: str) -> dict[str, str]:
    return dict(line.split("=", 1) for line in text.splitlines() if "=" in line and not line.startswith("#"))


class NotifySocket:
    """A fake systemd: a datagram socket that collects sd_notify messages."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(path))
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.sock.settimeout(0.05)
        self.messages: list[str] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._collect, daemon=True)
        self._thread.start()

    def _collect(self) -> None:
        while not self._stop.is_set():
            try:
                self.messages.append(self.sock.recv(4096).decode())
            except socket.timeout:
                continue

    def count(self, message: str) -> int:
        return sum(1 for m in list(self.messages) if message in m.split("\n"))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self.sock.close()


@NEEDS_SYSTEMD
@pytest.mark.parametrize("args, runs", [
    (("--fleet", "tls/station.local:7447", "--robot", "ugv_beast"), "serve"),
    (("--mission", str(PATROL), "--sim"), "run"),
])
def test_the_unit_passes_systemd_analyze_verify(tmp_path, args, runs):
    text = install(tmp_path, *args)
    unit = unit_values(text)
    assert unit["Type"] == "notify" and unit["Restart"] == "on-failure" and int(unit["WatchdogSec"]) > 0
    assert unit["StandardOutput"] == "journal" and unit["WantedBy"] == "multi-user.target"
    command = shlex.split(unit["ExecStart"])
    assert command[:4] == [sys.executable, "-m", "beastbt", runs]
    assert Path(unit["WorkingDirectory"]) == tmp_path
    groups = unit.get("SupplementaryGroups", "").split()
    assert set(groups) <= {"dialout", "i2c", "video", "gpio", "input"}
    done = subprocess.run(["systemd-analyze", "verify", str(tmp_path / "root/etc/systemd/system/beastbt.service")],
                          capture_output=True, text=True, timeout=60)
    # verify exits 0 on unknown keys or bad values and only warns: its silence is what passing means
    assert done.returncode == 0 and done.stderr.strip() == "" and done.stdout.strip() == "", done.stderr


def test_groups_come_from_the_target_roots_etc_group(tmp_path):
    (tmp_path / "root" / "etc").mkdir(parents=True)
    (tmp_path / "root" / "etc" / "group").write_text("root:x:0:\ndialout:x:20:pi\ni2c:x:998:pi\ngpio:x:997:pi\n")
    unit = unit_values(install(tmp_path, "--fleet", "tcp/station:7447", "--user", "pi"))
    assert unit["User"] == "pi" and unit["SupplementaryGroups"] == "dialout i2c gpio"


def test_install_needs_something_to_run_and_remove_takes_it_away(tmp_path):
    done = beastbt("service", "install", "--root", str(tmp_path / "root"), cwd=tmp_path)
    assert done.returncode == 2 and "--fleet ENDPOINT" in done.stderr and "--mission FILE" in done.stderr
    install(tmp_path, "--mission", str(PATROL))
    path = tmp_path / "root/etc/systemd/system/beastbt.service"
    assert beastbt("service", "status", "--root", str(tmp_path / "root"), cwd=tmp_path).returncode == 0
    done = beastbt("service", "remove", "--root", str(tmp_path / "root"), cwd=tmp_path)
    assert done.returncode == 0 and not path.exists()
    assert beastbt("service", "status", "--root", str(tmp_path / "root"), cwd=tmp_path).returncode == 1


def test_execstart_under_a_fake_notify_socket_is_ready_and_feeds_the_watchdog_every_tick(tmp_path):
    unit = unit_values(install(tmp_path, "--mission", str(PATROL), "--sim", "--", "--speed", "10",
                               "--no-record", "--max-time", "15 s", "--summary", str(tmp_path / "s.json")))
    notify = NotifySocket(tmp_path / "notify")
    try:
        done = subprocess.run(shlex.split(unit["ExecStart"]), cwd=unit["WorkingDirectory"], capture_output=True,
                              text=True, timeout=120,
                              env=dict(os.environ, PYTHONPATH=str(REPO), NOTIFY_SOCKET=str(notify.path)))
        time.sleep(0.3)  # the last datagrams are on their way to the collector thread
    finally:
        notify.close()
    assert done.returncode == 1, done.stdout + done.stderr  # stopped at max time: not a success
    ticks = json.loads((tmp_path / "s.json").read_text())["ticks"]
    assert ticks >= 299  # 15 s at 20 Hz
    assert notify.messages[0].split("\n")[0] == "READY=1"
    assert notify.count("WATCHDOG=1") == ticks


def test_a_stalled_loop_stops_feeding_the_watchdog(tmp_path, monkeypatch):
    """A tick that never returns (a hung device read, a behaviour in a loop) sends no keep-alive: systemd
    restarts the process when WatchdogSec passes. When the tick comes back, feeding resumes."""
    import beastbt.run.sd_notify as sd_notify
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute
    notify = NotifySocket(tmp_path / "notify")
    notifier = sd_notify.SystemdNotifier(str(notify.path))
    monkeypatch.setattr(sd_notify, "_PROCESS_NOTIFIER", notifier)
    p = prepare(str(PATROL), RunOptions(record=False, max_time_s=30.0, speed=20.0))
    stall, stalled = threading.Event(), threading.Event()
    real_tick = p.run.tick

    def tick():  # the 50th tick hangs until the test lets it go
        if p.run.ticks == 50 and not stall.is_set():
            stalled.set()
            stall.wait(10)
        return real_tick()

    monkeypatch.setattr(p.run, "tick", tick)
    runner = threading.Thread(target=execute, args=(p, open(os.devnull, "w")), daemon=True)
    try:
        runner.start()
        assert stalled.wait(30)
        time.sleep(0.2)
        before = notifier.sent_watchdogs
        time.sleep(1.0)  # a second of a stalled loop: at 20x, 1,000 ticks would have been fed
        assert notifier.sent_watchdogs == before >= 45  # one per tick done (a datagram may be lost under load)
        stall.set()
        runner.join(60)
        assert notifier.sent_watchdogs > before + 100
    finally:
        stall.set()
        runner.join(60)
        notify.close()
        notifier.close()
