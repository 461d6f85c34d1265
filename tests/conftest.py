"""Shared test helpers: paths of the repository and a way to write a mission file."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def write_mission(tmp_path: Path):
    """Write YAML text to a file in a temporary folder and return its path."""
    def _write(text: str, name: str = "m.yaml") -> Path:
        p = tmp_path / name
        p.write_text(text, encoding="utf-8")
        return p
    return _write
