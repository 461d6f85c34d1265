"""Ground-truth scores of line following in the simulator, for the run summary.

:class:`LineTruthMetrics` is a recorder of the tick loop (``run.recorders``).
While a ``follow_line`` step is RUNNING it samples, every tick, the distance
from the robot's true centre to the nearest line centreline
(:meth:`~beastbt.sim.floor.FloorMap.distance_to_line`), and it compares the
detector's junction reports with the floor's true junctions
(:meth:`~beastbt.sim.floor.FloorMap.junctions`):

* a junction is *passed* each time the robot's centre comes within
  ``pass_radius_m`` of it;
* a pass is *detected* when, since the previous pass of that junction, a
  reported intersection (placed in the world from the true pose and the
  reported distance ahead) fell within ``match_radius_m`` of it;
* a *false* intersection is a run of consecutive frames reporting one whose
  mean position is farther than ``match_radius_m`` from every true junction.

:meth:`LineTruthMetrics.summary` gives ``truth.line_error_p95_m``,
``line_within_5cm_frac``, ``line_error_max_m``, ``line_samples``,
``intersections_passed``, ``intersections_detected`` and ``false_intersections``.

A robot can follow a line for days: the samples are kept exactly for the
first :data:`EXACT_SAMPLES` (the p95 is then exact, as numpy computes it);
after that the p95 comes from a histogram of :data:`HISTOGRAM_BIN_M` bins
kept from the start, and the summary adds ``line_error_p95_resolution_m``.
The fraction within 5 cm, the largest error and the count are running
totals, exact however long the run.
"""

from __future__ import annotations

import math
from array import array
from typing import Any, Callable, Sequence

import numpy as np
import py_trees

from beastbt.blackboard.types import LineObservation
from beastbt.run.runner import TickRecord
from beastbt.sim.floor import FloorMap

WITHIN_M = 0.05
"""The field's bar: the fraction of time the centre is within this of the line (m)."""
EXACT_SAMPLES = 100_000
"""Errors kept one by one (8 bytes each, 800 kB at most): about 83 minutes of following at 20 Hz."""
HISTOGRAM_BIN_M = 0.001
"""Width of the histogram's bins (m): the p95's resolution once the run has more than :data:`EXACT_SAMPLES`."""
HISTOGRAM_BINS = 1000
"""Bins of the histogram: errors from 0 to 1 m; a larger error counts in the last bin."""


class LineTruthMetrics:
    """Scores of the follow_line steps ``nodes`` of one simulated run against the floor's truth (metres)."""

    def __init__(self, floor: Callable[[], FloorMap], nodes: Sequence[py_trees.behaviour.Behaviour],
                 pass_radius_m: float = 0.06, match_radius_m: float = 0.15) -> None:
        self._floor_fn = floor
        self.nodes = list(nodes)
        self.pass_radius_m = pass_radius_m
        self.match_radius_m = match_radius_m
        self.errors_m = array("d")
        """The first :data:`EXACT_SAMPLES` errors (m), in order."""
        self.samples = 0
        self.within = 0
        self.max_error_m = 0.0
        self._histogram = np.zeros(HISTOGRAM_BINS, dtype=np.int64)
        self.passes = 0
        self.detected = 0
        self.false = 0
        self._floor: Any = None
        self._junctions: np.ndarray = np.zeros((0, 2))
        self._inside: list[bool] = []
        self._flag: list[bool] = []
        self._episode: list[tuple[float, float]] = []

    def _ready(self) -> FloorMap:
        if self._floor is None:
            self._floor = self._floor_fn()
            js = self._floor.junctions()
            self._junctions = np.array([(x, y) for x, y, _ in js], float).reshape(-1, 2)
            self._inside = [False] * len(js)
            self._flag = [False] * len(js)
        return self._floor

    def on_tick(self, rec: TickRecord) -> None:
        """Recorder: sample the truth while a follow_line step runs."""
        if rec.truth is None or not any(n.status == py_trees.common.Status.RUNNING for n in self.nodes):
            self._close_episode()
            return
        floor = self._ready()
        t = rec.truth
        self.add(floor.distance_to_line(t.x, t.y))
        for r in rec.readings:
            if type(r) is not LineObservation:
                continue
            if r.seen and r.intersection and r.intersection_distance_m is not None:
                d = r.intersection_distance_m
                x, y = t.x + d * math.cos(t.yaw), t.y + d * math.sin(t.yaw)
                self._episode.append((x, y))
                i = self._nearest(x, y)
                if i is not None:
                    self._flag[i] = True
            else:
                self._close_episode()
        if len(self._junctions):
            dist = np.hypot(self._junctions[:, 0] - t.x, self._junctions[:, 1] - t.y)
            for i, inside in enumerate((dist <= self.pass_radius_m).tolist()):
                if inside and not self._inside[i]:
                    self.passes += 1
                    if self._flag[i]:
                        self.detected += 1
                    self._flag[i] = False
                self._inside[i] = inside

    def add(self, error_m: float) -> None:
        """Count one sample of the distance from the true centre to the line (m)."""
        self.samples += 1
        self.within += error_m <= WITHIN_M
        self.max_error_m = max(self.max_error_m, error_m)
        self._histogram[min(HISTOGRAM_BINS - 1, int(error_m / HISTOGRAM_BIN_M))] += 1
        if len(self.errors_m) < EXACT_SAMPLES:
            self.errors_m.append(error_m)

    def _p95_m(self) -> float:
        """The 95th percentile of the errors (m): exact while every sample is kept, else to a histogram bin."""
        if self.samples <= len(self.errors_m):
            return float(np.percentile(np.frombuffer(self.errors_m, dtype=np.float64), 95))
        rank = 0.95 * (self.samples - 1)  # numpy's linear method: the sample at this rank, counted from 0
        index = int(np.searchsorted(np.cumsum(self._histogram), math.floor(rank) + 1))
        return (index + 0.5) * HISTOGRAM_BIN_M

    def _nearest(self, x: float, y: float) -> Any:
        if not len(self._junctions):
            return None
        dist = np.hypot(self._junctions[:, 0] - x, self._junctions[:, 1] - y)
        i = int(np.argmin(dist))
        return i if dist[i] <= self.match_radius_m else None

    def _close_episode(self) -> None:
        if not self._episode:
            return
        mx, my = np.mean(np.array(self._episode), axis=0)
        self._episode = []
        if self._nearest(float(mx), float(my)) is None:
            self.false += 1

    def summary(self) -> dict:
        """The truth metrics (empty when no follow_line step ran)."""
        self._close_episode()
        if not self.samples:
            return {}
        out = {
            "line_error_p95_m": round(self._p95_m(), 4),
            "line_within_5cm_frac": round(self.within / self.samples, 4),
            "line_error_max_m": round(self.max_error_m, 4),
            "line_samples": self.samples,
            "intersections_passed": self.passes,
            "intersections_detected": self.detected,
            "false_intersections": self.false,
        }
        if self.samples > len(self.errors_m):  # a long run: the p95 is read off the histogram
            out["line_error_p95_resolution_m"] = HISTOGRAM_BIN_M
        return out


__all__ = ["LineTruthMetrics", "WITHIN_M"]
