""""Try it": a simulated run of the text in the editor, as ``beastbt run`` in a process of its own, with its console.

The run is the command a user types (``python -m beastbt run MISSION
--console 127.0.0.1:PORT --summary FILE``), so the studio tries exactly what
``beastbt run`` would do: as fast as the machine can by default
(``--speed max``; ``speed`` 10 or ``realtime`` when asked), capped by the run's
own default mission time unless ``max_time`` is given. The text runs as it is
in the editor, saved or not: from a hidden file beside the one it will be saved
as (so ``world:`` and geo files resolve from the same folder), removed when the
run ends. The run's folder goes to the studio folder's ``runs/``, where
``beastbt runs`` lists it; its summary, printed output and report go to a
temporary folder of the studio, removed when the studio ends.

The time left a try shows is wall time (:func:`mission_time_left`,
:func:`pace_of`): the mission time left, the console's own estimate, divided by
the speed-up measured from the console's own clock (mission seconds per wall
second over the last polls), so a run at ``--speed max`` does not show
real-time seconds.

At most :data:`MAX_RUNS` tries and test runs (:mod:`beastbt.studio.mission_tests`)
run at once: each takes one of as many slots before its process starts and
gives it back when its process has ended, so concurrent requests cannot start
more.
The console's own API is passed through (``/api/try/<id>/console/...``): the
console refuses to be framed by another page.
"""

from __future__ import annotations

import json
import math
import os
import secrets
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from beastbt.studio.files import FileRefused, StudioFolder, refusal_of

MAX_RUNS = 4
"""At most this many tries at once (each is a simulator process); older ended ones are forgotten first."""
STOP_WAIT_S = 1.0
"""When the studio ends, how long its tries have to stop after SIGTERM before they are killed (s): the studio
itself ends within 2 s of its own SIGTERM."""
KEPT_RUNS = 20
"""How many ended tries are remembered (their summary and report)."""
OUTPUT_LINES = 60
"""The last lines a run printed, kept for ``GET /api/try/<id>``."""
CONSOLE_PATHS = ("api/state", "api/map", "api/pause", "api/resume", "api/abort", "api/estop", "api/estop/reset",
                 "api/answer", "api/teleop")
"""The console's API passed through the studio (docs/console.md)."""
SPEED_WORDS = ("max", "realtime")
DEFAULT_SPEED = "max"
"""A try runs as fast as the machine can unless the request says otherwise."""
PACE_WINDOW_S = 10.0
"""The speed-up is measured over the console's states of about this many last wall seconds."""
PACE_MIN_SPAN_S = 0.5
"""No speed-up is given before the states span this many wall seconds (two polls a moment apart say little)."""
MAX_FACTOR = 1000.0
"""The largest factor of real time a try takes (above that, ``max`` is what is meant)."""
RECORDED_IN = "run recorded in "
"""How ``beastbt run`` names its run folder when it ends (beastbt/run/session.py)."""


@dataclass
class Trial:
    """One simulated run the studio started."""

    run_id: str
    process: subprocess.Popen
    folder: Path
    """The run's own temporary folder: summary, output, run folders."""
    mission_file: Path
    """The hidden copy of the text, removed when the run ends."""
    console_port: int
    output: deque = field(default_factory=lambda: deque(maxlen=OUTPUT_LINES))
    reader: Optional[threading.Thread] = None
    report: Optional[Path] = None
    report_error: Optional[str] = None
    speed: str = DEFAULT_SPEED
    runs_dir: Optional[Path] = None
    """Where the run's folder goes (the studio folder's ``runs/``)."""
    run_folder: Optional[Path] = None
    """The run's folder, once ``beastbt run`` has said where it recorded it."""
    pace: deque = field(default_factory=lambda: deque(maxlen=64))
    """(wall s, mission s) of the console states read through the studio: the measured speed-up."""

    @property
    def summary_file(self) -> Path:
        """Where ``--summary`` writes."""
        return self.folder / "summary.json"


def free_loopback_port() -> int:
    """A TCP port free on 127.0.0.1 now (the console binds it a moment later)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def speed_argument(value: Any) -> str:
    """``--speed`` of a try from the request's ``speed``: ``"max"`` (also when not given), ``"realtime"``, or a
    factor of real time above 0 (a number, or its text); FileRefused 400 otherwise."""
    if value is None:
        return DEFAULT_SPEED
    if isinstance(value, str) and value.strip() in SPEED_WORDS:
        return value.strip()
    if not isinstance(value, bool) and isinstance(value, (int, float, str)):
        try:
            factor = float(value)
        except ValueError:
            factor = math.nan
        if math.isfinite(factor) and 0 < factor <= MAX_FACTOR:
            return f"{factor:g}"
    raise FileRefused(400, f"'speed' is \"max\" (as fast as the machine can), \"realtime\" or a factor of real "
                           f"time from above 0 to {MAX_FACTOR:g} such as 10, not {json.dumps(value)[:40]}")


def mission_time_left(progress: dict) -> Optional[float]:
    """The mission seconds left (None: unknown): the console's ``progress.eta_s`` as it is. It credits the time the
    running step has run (:func:`beastbt.run.progress.eta_s`), so it falls through a step and is already measured
    at the run's own state, not the studio's less frequent polls (at 40 times real time, a poll every 0.4 s is
    16 s of mission time): taken back to a poll, or to the end of the last step, it would count a step's time
    twice."""
    eta = progress.get("eta_s")
    if not isinstance(eta, (int, float)) or isinstance(eta, bool) or not math.isfinite(eta):
        return None
    return max(0.0, float(eta))


def pace_of(samples: deque, eta_s: Optional[float], now_s: float) -> dict:
    """``{speedup, time_left_s}``: mission seconds per wall second over the last :data:`PACE_WINDOW_S` of
    ``samples`` ((wall s, mission s) pairs, oldest first), and the wall seconds left at that pace for ``eta_s``
    mission seconds left (None when either is unknown: too few samples, a paused run, no estimate)."""
    recent = [(w, m) for w, m in samples if now_s - w <= PACE_WINDOW_S]
    speedup: Optional[float] = None
    if len(recent) >= 2 and recent[-1][0] - recent[0][0] >= PACE_MIN_SPAN_S:
        speedup = (recent[-1][1] - recent[0][1]) / (recent[-1][0] - recent[0][0])
    left = None
    if speedup is not None and speedup > 1e-3 and eta_s is not None:
        left = round(eta_s / speedup, 1)
    return {"speedup": None if speedup is None else round(speedup, 2), "time_left_s": left}


class Trials:
    """The tries the studio started, by run id (see the module docstring)."""

    def __init__(self, folder: StudioFolder) -> None:
        self.folder = folder
        self.runs: dict[str, Trial] = {}
        self._lock = threading.Lock()
        self._slots = threading.BoundedSemaphore(MAX_RUNS)
        """One per try process: taken before it starts, given back by its reader when it has ended."""
        self._closing = False
        self._reports: set[subprocess.Popen] = set()
        """The ``beastbt report`` processes making a try's report now."""

    def start(self, text: str, path: Optional[str], body: dict) -> dict:
        """Start a try of ``text`` (saved or not at ``path``): ``{run_id, console_url}``; raises FileRefused."""
        from beastbt.core.units import UnitError, parse_duration
        speed = speed_argument(body.get("speed"))
        robot = body.get("robot") or "sim"
        if not isinstance(robot, str):
            raise FileRefused(400, "'robot' is a robot profile's name or the path of a robot file")
        from beastbt.studio.analysis import robot_argument
        robot = robot_argument(self.folder, robot)  # inside the folder, or a shipped profile (file_refs)
        # no cap of the studio's own: the run's (beastbt run's default mission time) unless the request gives one
        max_time = body.get("max_time")
        if max_time is not None:
            try:
                if isinstance(max_time, bool) or parse_duration(max_time) <= 0:
                    raise UnitError("give a time above 0 such as '10 min'")
            except (UnitError, TypeError, ValueError) as exc:
                raise FileRefused(400, f"'max_time': {exc}") from None
        seed = body.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise FileRefused(400, "'seed' is a whole number, 0 or more")
        target = self.folder.resolve(path, must_exist=False) if path else self.folder.root / "untitled.yaml"
        self.take_slot("try")
        try:
            return self._start(text, target, robot, speed, None if max_time is None else str(max_time), seed)
        except BaseException:
            self._slots.release()
            raise

    def take_slot(self, what: str) -> None:
        """Take one of the :data:`MAX_RUNS` slots for a simulator process (a try, or a test run); FileRefused 409
        when all are taken, 503 when the studio is ending. :meth:`give_slot` gives it back."""
        if self._closing:
            raise FileRefused(503, f"the studio is ending: no new {what} starts")
        if not self._slots.acquire(blocking=False):
            # the slot is taken atomically: of many requests at once, only MAX_RUNS get one
            raise FileRefused(409, f"{MAX_RUNS} tries and test runs are running already (at most {MAX_RUNS} at "
                                   f"once): stop one first (POST /api/try/RUN_ID/stop or /api/test/TEST_ID/stop)")

    def give_slot(self) -> None:
        """Give back a slot :meth:`take_slot` took (its process has ended)."""
        self._slots.release()

    def _start(self, text: str, target: Path, robot: str, speed: str, max_time: Optional[str], seed: int) -> dict:
        """Start the try's process, with a slot already taken (the reader gives it back when the process ends)."""
        with self._lock:
            self._forget_old()
        here = target.parent if target.parent.is_dir() else self.folder.root
        run_id = secrets.token_hex(6)
        mission_file = here / f".{target.stem}.try-{run_id}.yaml"
        try:
            mission_file.write_text(text, encoding="utf-8")
            run_folder = Path(tempfile.mkdtemp(prefix=f"beastbt-studio-try-{run_id}-"))
        except OSError as exc:
            mission_file.unlink(missing_ok=True)
            raise refusal_of(exc, "the try did not start") from None
        port = free_loopback_port()
        runs_dir = self.folder.root / "runs"  # beastbt runs, run in the folder, lists the tries with the other runs
        command = [sys.executable, "-m", "beastbt", "run", str(mission_file), "--robot", robot,
                   "--speed", speed, "--seed", str(seed),
                   "--console", f"127.0.0.1:{port}", "--summary", str(run_folder / "summary.json"),
                   "--runs-dir", str(runs_dir), "--files-inside", str(self.folder.root)]
        if max_time is not None:
            command += ["--max-time", max_time]
        if robot != "sim":
            command.append("--sim")  # a real robot's profile on the simulator: a try never moves a robot
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        try:
            process = subprocess.Popen(command, cwd=run_folder, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                       stderr=subprocess.STDOUT, text=True, errors="replace", env=env)
        except OSError:
            mission_file.unlink(missing_ok=True)
            shutil.rmtree(run_folder, ignore_errors=True)
            raise
        trial = Trial(run_id, process, run_folder, mission_file, port, speed=speed, runs_dir=runs_dir)
        with self._lock:
            self.runs[run_id] = trial
        trial.reader = threading.Thread(target=self._read_output, args=(trial,), name=f"beastbt-try-{run_id}",
                                        daemon=True)
        trial.reader.start()
        if self._closing:  # the studio began to end while this one started: it must not outlive the studio
            process.kill()
        return {"run_id": run_id, "console_url": f"http://127.0.0.1:{port}/", "state": "running"}

    def _read_output(self, trial: Trial) -> None:
        """Keep the last lines the run prints; when it ends, remove the hidden copy of the text."""
        assert trial.process.stdout is not None
        name = str(trial.mission_file)
        for line in trial.process.stdout:
            line = line.rstrip("\n")
            if line.startswith(RECORDED_IN) and trial.runs_dir is not None:
                recorded = Path(line[len(RECORDED_IN):].strip())
                if recorded.parent.resolve() == trial.runs_dir.resolve():  # only a folder of the studio's runs/
                    trial.run_folder = recorded
            trial.output.append(line.replace(name, "(the text in the studio)"))
        trial.process.wait()
        self._slots.release()
        trial.mission_file.unlink(missing_ok=True)

    def _forget_old(self) -> None:
        ended = [t for t in self.runs.values() if t.process.poll() is not None]
        for trial in ended[:max(0, len(ended) - KEPT_RUNS)]:
            del self.runs[trial.run_id]
            shutil.rmtree(trial.folder, ignore_errors=True)

    def get(self, run_id: str) -> Trial:
        """The try called ``run_id``; FileRefused 404 when there is none."""
        trial = self.runs.get(run_id)
        if trial is None:
            raise FileRefused(404, f"no try '{run_id[:40]}' (the studio forgets tries when it stops)")
        return trial

    def state(self, run_id: str) -> dict:
        """``{run_id, state, exit_code?, summary?, report?, output, console_url}`` of a try."""
        trial = self.get(run_id)
        code = trial.process.poll()
        out: dict[str, Any] = {"run_id": run_id, "state": "running" if code is None else "ended",
                               "console_url": f"http://127.0.0.1:{trial.console_port}/", "speed": trial.speed,
                               "output": list(trial.output)}
        if code is not None:
            if trial.reader is not None:
                trial.reader.join(2.0)  # the last lines, and the copy removed
                out["output"] = list(trial.output)
            out["exit_code"] = code
            try:
                out["summary"] = json.loads(trial.summary_file.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                out["summary"] = None
            folder = self._run_folder(trial)
            if folder is not None:
                out["report"] = f"/api/try/{run_id}/report/"
                out["run_folder"] = self._shown(folder)
        return out

    def stop(self, run_id: str) -> dict:
        """End a try (as Ctrl-C would: the run stops the robot, writes its summary) and answer its state.

        SIGTERM, which ``beastbt run`` takes as Ctrl-C: not SIGINT, which a studio started from a script's
        background job (``beastbt studio &``) hands its tries ignored (POSIX), so that they would not stop."""
        trial = self.get(run_id)
        if trial.process.poll() is None:
            trial.process.terminate()
            try:
                trial.process.wait(10.0)
            except subprocess.TimeoutExpired:
                trial.process.kill()
                trial.process.wait(5.0)
        return self.state(run_id)

    def begin_stop(self) -> None:
        """Refuse new tries and send SIGTERM to those running, without waiting (the studio is ending: they stop
        while it closes its server)."""
        self._closing = True
        for trial in list(self.runs.values()):
            if trial.process.poll() is None:
                trial.process.terminate()
        with self._lock:
            reports = list(self._reports)
        for making in reports:
            making.kill()  # a report of a try whose folder is about to go

    def stop_all(self, wait_s: float = STOP_WAIT_S) -> None:
        """Stop every try still running and remove every try's temporary folder (the studio is ending): SIGTERM,
        then SIGKILL for those still running after ``wait_s`` seconds in all."""
        import time
        trials = list(self.runs.values())
        self.begin_stop()
        deadline = time.monotonic() + wait_s
        for trial in trials:
            try:
                trial.process.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                trial.process.kill()
                try:
                    trial.process.wait(1.0)
                except subprocess.TimeoutExpired:
                    pass
            trial.mission_file.unlink(missing_ok=True)
            shutil.rmtree(trial.folder, ignore_errors=True)

    @staticmethod
    def _run_folder(trial: Trial) -> Optional[Path]:
        """The try's own run folder (others' runs share ``runs/``), when the run wrote one."""
        if trial.reader is not None:
            trial.reader.join(2.0)  # its last line names the folder
        folder = trial.run_folder
        return folder if folder is not None and (folder / "summary.json").is_file() else None

    def _shown(self, folder: Path) -> str:
        """``runs/NAME`` relative to the studio folder (the way ``beastbt runs`` there names it)."""
        try:
            return folder.resolve().relative_to(self.folder.root.resolve()).as_posix()
        except ValueError:
            return str(folder)

    def report_file(self, run_id: str) -> Path:
        """The HTML report of an ended try, made with ``beastbt report`` the first time it is asked for."""
        trial = self.get(run_id)
        if trial.process.poll() is None:
            raise FileRefused(409, "the try is still running: its report comes when it has ended")
        if trial.report is not None and trial.report.is_file():
            return trial.report
        run_folder = self._run_folder(trial)
        if run_folder is None:
            raise FileRefused(404, "this try wrote no run folder (it did not start: see its output)")
        out = trial.folder / "report"
        if self._closing:
            raise FileRefused(503, "the studio is ending: no report is made")
        making = subprocess.Popen([sys.executable, "-m", "beastbt", "report", str(run_folder), "--out", str(out)],
                                  cwd=trial.folder, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)
        with self._lock:
            self._reports.add(making)  # the studio ending kills it with the tries
        try:
            stdout, stderr = making.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            making.kill()
            stdout, stderr = making.communicate()
        finally:
            with self._lock:
                self._reports.discard(making)
        html = out / "report.html"
        if making.returncode != 0 or not html.is_file():
            raise FileRefused(500 if making.returncode != 2 else 404,
                              f"the report could not be made: {(stderr or stdout).strip()[-300:]}")
        trial.report = html
        return html

    def report_asset(self, run_id: str, name: str) -> Path:
        """A file the report refers to (its plots), inside the report's folder only."""
        html = self.report_file(run_id)
        root = html.parent.resolve()
        target = (root / name).resolve()
        if root not in target.parents or not target.is_file():
            raise FileRefused(404, f"no file '{name[:80]}' in the report")
        return target

    async def console(self, run_id: str, method: str, what: str, body: Optional[bytes]) -> tuple[int, Any]:
        """Pass one request to the try's console: (status, JSON answer)."""
        import aiohttp
        trial = self.get(run_id)
        if what not in CONSOLE_PATHS or (method == "GET") != (what in ("api/state", "api/map")):
            return 404, {"error": f"the console has no {method} /{what[:60]} (see docs/console.md)"}
        if trial.process.poll() is not None:
            return 409, {"error": "the try has ended: its console is closed (see GET /api/try/RUN_ID)"}
        url = f"http://127.0.0.1:{trial.console_port}/{what}"
        try:
            async with aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=5)) as session:
                async with session.request(method, url, data=body if body is not None else None,
                                           headers={"Content-Type": "application/json"} if body is not None else {}
                                           ) as answer:
                    try:
                        data = await answer.json(content_type=None)
                    except ValueError:
                        return 502, {"error": "the console answered something that is not JSON"}
                    if what == "api/state" and answer.status == 200 and isinstance(data, dict):
                        data["pace"] = self._pace(trial, data)
                    return answer.status, data
        except (aiohttp.ClientError, OSError, TimeoutError):
            return 503, {"error": "the try's console does not answer (yet): it starts a moment after the run"}


    @staticmethod
    def _pace(trial: Trial, state: dict) -> dict:
        """The console's state's ``pace``: the measured speed-up and the wall time left (:func:`pace_of`)."""
        import time
        now = time.monotonic()
        sim = state.get("time_s")
        if isinstance(sim, (int, float)) and not isinstance(sim, bool):
            if not trial.pace or trial.pace[-1][1] != sim or now - trial.pace[-1][0] > PACE_MIN_SPAN_S:
                trial.pace.append((now, float(sim)))
        progress = state.get("progress") if isinstance(state.get("progress"), dict) else {}
        return pace_of(trial.pace, mission_time_left(progress), now)


__all__ = ["Trial", "Trials", "free_loopback_port", "mission_time_left", "pace_of", "speed_argument"]
