"""``beastbt runs``: the recorded runs, one line each, oldest first.

Each line: the run folder's name, the mission, the outcome, the mission time,
the distance, and the recording's size and dropped messages. The outcome
comes from ``summary.json``; a run without one did not finish (killed, or
still running), and its line says so; an empty one is a run that ended on a
full disk (``beastbt recover RUN`` rebuilds a summary from the recording).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from beastbt.run.retention import KEEP_MARKER, is_running


NO_SUMMARY = "no summary (disk full?)"
"""The status of a run whose ``summary.json`` is empty: it ended, but the summary could not be written."""


@dataclass
class RunEntry:
    """One run folder as ``beastbt runs`` lists it."""

    folder: Path
    mission: str
    status: str
    sim_time_s: Optional[float]
    distance_m: Optional[float]
    mcap_bytes: Optional[int]
    dropped: Optional[int]

    def cells(self) -> tuple[str, str, str, str, str, str]:
        """The run's columns as texts: folder, mission, outcome, mission time, distance, recording."""
        t = f"{self.sim_time_s:.1f} s" if self.sim_time_s is not None else "? s"
        dist = f"{self.distance_m:.2f} m" if self.distance_m is not None else "? m"
        if self.mcap_bytes is None:
            rec = "not recorded"
        else:
            rec = f"run.mcap {self.mcap_bytes / 1e6:.2f} MB"
            if self.dropped:
                rec += f", {self.dropped} dropped"
        return self.folder.name, self.mission, self.status, t, dist, rec

    def line(self) -> str:
        """The run in one line (columns as wide as this run needs; :func:`table` lines up many)."""
        return "  ".join(self.cells())


HEADER = ("RUN", "MISSION", "OUTCOME", "TIME", "DISTANCE", "RECORDING")
"""The column titles of ``beastbt runs``."""
WIDEST = (48, 32, 40)
"""The widest the run, mission and outcome columns get (characters); longer texts end in an ellipsis."""


def _fit(text: str, width: int) -> str:
    return text if len(text) <= width else text[: width - 1] + "…"


def table(entries: list[RunEntry]) -> list[str]:
    """``beastbt runs``'s lines: a header, then one line per run, in columns as wide as the widest entry (up to
    :data:`WIDEST`), the time and distance right-aligned."""
    rows = [HEADER] + [e.cells() for e in entries]
    rows = [tuple(_fit(c, WIDEST[i]) if i < len(WIDEST) else c for i, c in enumerate(r)) for r in rows]
    widths = [max(len(r[i]) for r in rows) for i in range(len(HEADER))]
    out = []
    for r in rows:
        cols = [c.rjust(widths[i]) if i in (3, 4) else c.ljust(widths[i]) for i, c in enumerate(r)]
        out.append("  ".join(cols).rstrip())
    return out


def list_runs(runs_dir: str) -> list[RunEntry]:
    """Every run folder in ``runs_dir`` (a folder with ``summary.json`` or ``run.mcap``), sorted by name (time)."""
    root = Path(runs_dir)
    if not root.is_dir():
        return []
    out = []
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        summary_path, mcap = folder / "summary.json", folder / "run.mcap"
        if not summary_path.exists() and not mcap.exists():
            continue
        summary: dict = {}
        if summary_path.exists():
            try:
                text = summary_path.read_text(encoding="utf-8")
                # Empty: the run ended but its summary could not be written (a full disk): see its events.
                summary = json.loads(text) if text.strip() else {"status": NO_SUMMARY}
            except (OSError, ValueError):
                summary = {"status": "unreadable"}
        mission = summary.get("mission") or _mission_from_name(folder.name)
        status = summary.get("status") or ("running" if is_running(folder) else "unfinished")
        if summary.get("recovered"):
            status = f"cut short ({status}, recovered)"  # rebuilt by ``beastbt recover`` from the recording
        if (folder / KEEP_MARKER).exists():
            status += " [kept]"  # ``beastbt runs keep``: never pruned
        out.append(RunEntry(folder, mission, status, summary.get("sim_time_s"), summary.get("distance_m"),
                            mcap.stat().st_size if mcap.exists() else None,
                            (summary.get("recording") or {}).get("dropped")))
    return out


def _mission_from_name(name: str) -> str:
    """``20250101T120000Z_patrol`` -> ``patrol`` (the folder name when the summary is missing)."""
    return name.split("_", 1)[1] if "_" in name else name


__all__ = ["list_runs", "RunEntry", "table"]
