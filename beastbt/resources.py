"""Where beastbt's bundled files are: schemas, robot profiles and worlds.

Installed, they are package data (``beastbt.schemas``, ``beastbt.robots``,
``beastbt.worlds``); in a source checkout imported from its root (as
``python -m pytest`` does) they are the top-level folders beside ``beastbt/``.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Union

from importlib.abc import Traversable


def data_dir(name: str) -> Union[Traversable, Path]:
    """The folder of bundled files called ``name`` (``schemas``, ``robots`` or ``worlds``)."""
    try:
        return resources.files(f"beastbt.{name}")
    except ModuleNotFoundError:
        return Path(__file__).resolve().parent.parent / name
