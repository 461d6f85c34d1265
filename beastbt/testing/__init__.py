"""Testing missions: the tick-by-tick harness, mission test files (``*.test.yaml``), their faults and substitutions.

- :mod:`~beastbt.testing.harness`: :class:`MissionHarness`, a mission ticked by hand on the simulator.
- :mod:`~beastbt.testing.spec`: a test file loaded and checked (``schemas/test.schema.json``), positioned errors.
- :mod:`~beastbt.testing.faults`: the events of a test (GPS lost, LiDAR silent, a person...) and the forced
  results of steps, carried out through the simulator's devices and the console's controls.
- :mod:`~beastbt.testing.expectations`: what a run's summary must show, each failure in words.
- :mod:`~beastbt.testing.runs`: one test file x seed run at full speed, recorded under ``runs/``.
- :mod:`~beastbt.testing.pytest_plugin`: pytest collects ``*.test.yaml`` (entry point ``pytest11``).

``from beastbt.testing import MissionHarness`` is the programmer's way in.
"""

from typing import Any

__all__ = ["MissionHarness"]


def __getattr__(name: str) -> Any:
    """``MissionHarness`` on first use: the pytest plugin (loaded by every pytest session where beastbt is
    installed) imports this package, and must not import the run, the simulator and py_trees to start."""
    if name == "MissionHarness":
        from beastbt.testing.harness import MissionHarness
        return MissionHarness
    raise AttributeError(f"module 'beastbt.testing' has no attribute {name!r}")
