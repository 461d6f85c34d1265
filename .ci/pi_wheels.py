"""Prove that a 64-bit Raspberry Pi OS (Bookworm: Python 3.11, aarch64, glibc 2.36) installs beastbt without
compiling anything: pip downloads a binary wheel of every run-time dependency (and of the `video` extra's PyAV,
which the Pi's H.264 encoder needs) for manylinux_2_28_aarch64 and CPython 3.11, and resolves them together.

Run by .ci/run; by hand: `python3 .ci/pi_wheels.py [--keep DIR]`. Exit 0 when every wheel is there, else pip's
own exit status with its message (a dependency without an aarch64 wheel is named there).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

PLATFORM = "manylinux_2_28_aarch64"
"""The Pi's wheel tag: Bookworm's glibc is 2.36, so manylinux_2_28 and every older manylinux tag install there."""
PLATFORMS = [f"manylinux_2_{minor}_aarch64" for minor in range(28, 16, -1)] + ["manylinux2014_aarch64"]
"""What pip is told: it takes ``--platform`` tags literally (a manylinux_2_28 machine also installs
manylinux_2_17 wheels, but pip's download does not widen the tag by itself), so every tag up to 2_28 is named."""
PYTHON = "3.11"
"""Bookworm's python3."""
EXTRAS = ("video",)
"""Extras a robot installs besides the run-time dependencies (not the test extras)."""


def requirements(pyproject: Path) -> list[str]:
    """The project's run-time dependencies plus the robot's extras, as pip requirement strings."""
    project = tomllib.loads(pyproject.read_text(encoding="utf-8"))["project"]
    found = list(project["dependencies"])
    for extra in EXTRAS:
        found += project.get("optional-dependencies", {}).get(extra, [])
    return list(dict.fromkeys(found))


def main() -> int:
    """Download the wheels into a temporary folder (or ``--keep DIR``) and report what came."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", metavar="DIR", help="download into DIR and keep it (default: a temporary folder)")
    args = parser.parse_args()
    pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
    with tempfile.TemporaryDirectory() as tmp:
        dest = Path(args.keep or tmp)
        dest.mkdir(parents=True, exist_ok=True)
        command = [sys.executable, "-m", "pip", "download", "--quiet", "--only-binary=:all:",
                   *(arg for tag in PLATFORMS for arg in ("--platform", tag)), "--python-version", PYTHON,
                   "--implementation", "cp", "--dest", str(dest), *requirements(pyproject)]
        done = subprocess.run(command)
        if done.returncode != 0:
            print(f"pi wheels: FAILED: a dependency has no binary wheel for {PLATFORM}, CPython {PYTHON} "
                  f"(pip's message above names it)", file=sys.stderr)
            return done.returncode
        wheels = sorted(p.name for p in dest.glob("*.whl"))
        others = sorted(p.name for p in dest.iterdir() if not p.name.endswith(".whl"))
        if others:
            print(f"pi wheels: FAILED: not wheels: {', '.join(others)}", file=sys.stderr)
            return 1
        print(f"pi wheels: {len(wheels)} wheels for {PLATFORM}, CPython {PYTHON}: nothing to compile on a 64-bit Pi")
    return 0


if __name__ == "__main__":
    sys.exit(main())
