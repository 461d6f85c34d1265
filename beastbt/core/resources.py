"""Where beastbt's bundled files are: schemas, robot profiles and worlds.

Installed, they are package data (``beastbt.schemas``, ``beastbt.robots``,
``beastbt.worlds``); in a source checkout imported from its root (as
``python -m pytest`` does) they are the top-level folders beside ``beastbt/``.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any


def data_dir(name: str) -> Any:
    """The folder of bundled files called ``name`` (``schemas``, ``robots`` or ``worlds``).

    Returns an ``importlib.resources`` Traversable or a ``pathlib.Path``; both have ``/``, ``iterdir`` and ``read_text``.
    """
    try:
        return resources.files(f"beastbt.{name}")
    except ModuleNotFoundError:
        return Path(__file__).resolve().parents[2] / name
