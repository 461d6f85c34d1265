"""Ending a process that opened a Zenoh session, without the interpreter's finalization.

Zenoh's Python binding runs Rust threads that call into Python (a subscriber's
callback, a dropped closure, a connection retry's bookkeeping). CPython before
3.14 ends a foreign thread that asks for the GIL while the interpreter
finalizes with ``pthread_exit``, whose forced unwinding through the Rust frames
aborts the whole process (glibc prints ``FATAL: exception not rethrown``, the
exit status is SIGABRT): a run that succeeded would end as a crash, most often
on a loaded machine (CPython gh-87135; PyO3 #4874). Once beastbt's own work is
done (summary written, recording closed, the session closed), the process runs
what the interpreter would (non-daemon threads joined, ``atexit`` functions,
streams flushed) and ends with ``os._exit``, so no Rust thread can meet a
finalizing interpreter.
"""

from __future__ import annotations

import atexit
import os
import sys
import threading
from typing import NoReturn


def needs_quick_end() -> bool:
    """Whether this process loaded Zenoh's binding (its threads may call into Python at exit)."""
    return "zenoh" in sys.modules


def end_process(status: int) -> NoReturn:
    """End the process with ``status`` (0-255) as the interpreter would, but without finalizing it (see the module
    docstring): the other non-daemon threads are waited for, ``atexit`` functions run, the standard streams are
    flushed, then ``os._exit``."""
    me = threading.current_thread()
    for thread in threading.enumerate():
        if thread is not me and not thread.daemon and thread.is_alive():
            thread.join()
    atexit._run_exitfuncs()  # what Py_Finalize would run first: logging's flush, multiprocessing's clean-up
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass  # the reader went away, or the stream is closed: nothing more to say
    os._exit(status & 0xFF)
