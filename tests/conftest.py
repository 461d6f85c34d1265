"""Shared test helpers: paths of the repository and a way to write a mission file."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

# Tests press Ctrl-C on the runs they start (SIGINT to a child process). A test session started from a script's
# background job (``./.ci/run &``) has SIGINT ignored, POSIX's rule for such jobs, and every child inherits that:
# its run would never see the Ctrl-C. The children here get SIGINT's default, as a terminal's command does.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture
def write_mission(tmp_path: Path):
    """Write YAML text to a file in a temporary folder and return its path."""
    def _write(text: str, name: str = "m.yaml") -> Path:
        p = tmp_path / name
        p.write_text(text, encoding="utf-8")
        return p
    return _write
