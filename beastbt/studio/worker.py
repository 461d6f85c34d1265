"""A worker process of the studio: it checks, compiles, draws and edits texts, one at a time, for the server.

The studio starts a few of these (``python -m beastbt.studio.worker FOLDER
MEMORY_BYTES``, see :mod:`beastbt.studio.work_pool`) and kills one that takes
too long or whose client has gone: a Python thread cannot be stopped, a
process can. Each worker warms up (imports the schemas, the compiler and the
parts, about a second), then limits its own address space to ``MEMORY_BYTES``
(``RLIMIT_AS``), so a text that would take gigabytes ends in a MemoryError here,
not in the kernel killing something else on the machine.

The protocol is one JSON line each way on stdin and on stdout (stray prints of
the libraries go to stderr). First the worker says ``{"ready": PID}``; then for
each job ``{op: validate|tree|map|edit, text, path, robot, edit, cpu_s}`` it
answers one of:

* ``{"answer": {...}}``: the JSON of docs/studio.md;
* ``{"refused": STATUS, "error": "...", "line"?, "column"?}``: a 4xx for the client;
* ``{"too_large": "memory"}``: the job ran out of the address space (the worker then ends: its heap is
  not to be trusted; the studio starts another);
* ``{"failed": "..."}``: a slip of beastbt's (the studio answers 500 with it).

``cpu_s`` bounds the job's CPU time (``RLIMIT_CPU``) as a backstop: a worker
whose studio was killed does not compute on for minutes.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import sys
from pathlib import Path
from typing import Any, Callable, TextIO

MEMORY_MESSAGE = "MemoryError"
"""How :func:`beastbt.validate.internal_error` names a MemoryError it caught inside a check."""
NESTING_CHECK_AT = 200
"""An edit's text that could nest this deep (brackets and braces, plus its longest line) is read with beastbt's
YAML reader first, which says where it nests too deeply: ruamel.yaml would recurse for seconds and then fail."""


def _job(folder: Any, job: dict) -> dict:
    """One job's answer (see the module docstring)."""
    from beastbt.studio import analysis
    from beastbt.studio.files import FileRefused
    text, path, robot = job["text"], job.get("path"), job.get("robot")
    try:
        if job["op"] == "edit":
            return _edit(text, job["edit"])
        fn: Callable[..., dict] = {"validate": analysis.validate_text, "tree": analysis.tree_of,
                                   "map": analysis.map_of}[job["op"]]
        answer = fn(folder, text, path, robot)
    except FileRefused as exc:
        return {"refused": exc.status, "error": str(exc)}
    if any(MEMORY_MESSAGE in p.get("message", "") and p.get("message", "").startswith("internal error")
           for p in answer.get("problems", [])):
        raise MemoryError  # a check caught it and called it a slip: it is the text's size, and the heap is suspect
    return {"answer": answer}


def _edit(text: str, edit: dict) -> dict:
    """``POST /api/edit``'s answer, or its 400 (a text nested too deeply to edit is refused where it nests)."""
    from beastbt.core.errors import InvalidInput
    from beastbt.studio.edits import EditRefused, apply_edit
    if text.count("[") + text.count("{") + max(map(len, text.splitlines()), default=0) >= NESTING_CHECK_AT:
        from beastbt.core.yaml_source import load_yaml
        try:
            load_yaml("edit.yaml", text=text, display_name="edit.yaml")
        except InvalidInput as exc:
            errors = [p for p in exc.problems if p.severity == "error"] or exc.problems
            first = errors[0]
            return {"refused": 400, "error": f"{first.message}: the map cannot edit this text" +
                    (f" ({first.hint})" if first.hint else ""), "line": first.position.line,
                    "column": first.position.column}
    try:
        return {"answer": apply_edit(text, edit)}
    except EditRefused as exc:
        return {"refused": 400, "error": str(exc), **exc.where()}
    except RecursionError:
        return {"refused": 400, "error": "the text nests too deeply to edit: keep lists and mappings within 100 "
                                         "levels", "line": 1, "column": 1}


def _warm_up(folder: Any) -> None:
    """Check a template once, so that the first request is as quick as the next; load OpenCV (a map's picture)
    with one thread, so that what it maps is counted before the address space is capped, whatever the cores."""
    import cv2
    cv2.setNumThreads(1)  # one job at a time: a pool of threads would only take address space
    from beastbt.studio.analysis import tree_of
    from beastbt.studio.templates import template_text
    try:
        tree_of(folder, template_text(folder, "gps_route", {}), None, None)
    except Exception:  # noqa: BLE001 - a warm-up only; the real request says what is wrong
        pass


def _limit_memory(limit_bytes: int) -> None:
    """Cap this process's address space at ``limit_bytes`` (never below what it uses warm, plus 64 MB)."""
    try:
        with open("/proc/self/statm", encoding="ascii") as f:
            in_use = int(f.read().split()[0]) * resource.getpagesize()
    except (OSError, ValueError, IndexError):
        in_use = 0
    limit = max(limit_bytes, in_use + (64 << 20))
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))


def _limit_cpu(seconds: float) -> None:
    """Let the next job use at most ``seconds`` more of CPU time (then the kernel ends this process)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    soft = int(usage.ru_utime + usage.ru_stime + seconds) + 1
    _, hard = resource.getrlimit(resource.RLIMIT_CPU)
    if hard != resource.RLIM_INFINITY:
        soft = min(soft, hard)
    resource.setrlimit(resource.RLIMIT_CPU, (soft, hard))


def _send(channel: TextIO, message: dict) -> None:
    channel.write(json.dumps(message) + "\n")
    channel.flush()


def main(argv: list[str]) -> int:
    """Serve jobs from stdin until it closes; 0."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole terminal: the studio ends its workers
    channel = os.fdopen(os.dup(1), "w", encoding="utf-8")
    os.dup2(2, 1)  # a library's print must not end up in the answers
    from beastbt.studio.files import StudioFolder
    folder = StudioFolder(Path(argv[0]))
    _warm_up(folder)
    _limit_memory(int(argv[1]))
    _send(channel, {"ready": os.getpid()})
    for line in sys.stdin:
        try:
            job = json.loads(line)
            _limit_cpu(float(job.get("cpu_s", 120.0)))
            message = _job(folder, job)
        except MemoryError:
            message = None
        except Exception as exc:  # noqa: BLE001 - the studio answers 500 with it, and this worker serves on
            message = {"failed": f"{type(exc).__name__}: {str(exc)[:200]}"}
        if message is None:
            _send(channel, {"too_large": "memory"})
            return 0
        _send(channel, message)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
