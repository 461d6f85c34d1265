"""People in the LiDAR: tracking what walks, and stepping aside for a person who walks at the robot.

Nothing here knows the simulator: a person is what the scans show, a small
blob that moves.

:class:`PersonTracker` takes each new scan with the odom poses of the last
second. It cuts the scan, in the order measured, into runs of returns less
than ``JUMP_M`` apart; a run of at least ``MIN_POINTS`` returns, at most
``MAX_WIDTH_M`` across and in front of what the beams beside it hit (the
classic cue of a leg or body detector: a wall seen at a grazing angle is
not in front of its own continuation) is a *blob*. Its centre is the mean
of its returns pushed back along the beam by a part of its half-width (the
LiDAR sees the near side of a body), placed in ``odom`` with the pose at the
time its beams were measured. Blobs are matched to tracks by nearest
neighbour within ``GATE_M`` of each track's prediction; a track's velocity
is the least-squares slope of its centres over the last ``HISTORY_S``; a
track not seen for ``LOST_S`` is dropped. A track is a *walking person*
once it has been followed for ``CONFIRM_S`` at ``person_min_speed_mps`` or
more, standing all that time where the scans of ``FREE_AGE_S`` before saw
free space (a person walks into space that was free; a wall is where it was).
That look back is what keeps walls out: a beam returning nothing (1-2 % of
them) cuts a short piece out of a wall that is "in front of" its neighbours,
and as the robot moves round a corner that piece's centre slides along the
wall at walking speed for more than ``CONFIRM_S``. Positions are metres in ``odom``, velocities m/s, times the scans'
stamps (s). :meth:`PersonTracker.without_walkers` is the scan the global
costmap marks: without the walking persons' returns.

:class:`PassingPlanner` is the local planner (:class:`DwaPlanner`) with the
rule people expect in a corridor. A walking person who comes toward the
robot's way (within 60 deg of head-on), whose line will pass within the
*passing distance* (the footprint radius + the person's + ``pass_clearance_m``)
of the robot's line, and who would meet it within ``pass_react_time_s``, is
passed on a side (one who catches the robot up from behind on its line is let
by the same way): the carrot and the goal the planner steers for are moved
sideways until they lie the passing distance beyond the person's line (the
lanes run along the person's walk), so the robot changes lanes, drives on
beside the person and moves back once the person is behind it. Until it is
in its lane it steers for the lane just ahead at the profile's top speed,
driving that arc as it is while the footprint would touch nothing on it.
The side is ``pass_side`` (``right`` by default, as people keep right) when
the local costmap has room for the robot there (cells below the inscribed
cost, a margin beyond; down to half the clearance closer) and it can get
there before the person; else the other side; when neither is in time, the
side that needs the shorter step; when neither has room, it stops and waits
(the collision monitor, below the tree, still has the last word on every
command). Where the walls leave less room than half the clearance on both
sides, a *tight* lane is taken (down to ``PASS_MIN_CLEARANCE_M``), and the
robot stands in it once the person is ``TIGHT_STOP_S`` away. The person
counts at least ``PASS_RADIUS_MIN_M`` in radius; their line is fitted to their
centres (``LANE_HISTORY_S`` of them once passing), and runs along the walls
(the local costmap's longest straight line of marks, :func:`wall_direction`)
when the fitted direction is within ``WALL_SNAP_DEG`` of theirs
(``WALL_KEEP_DEG`` once fitted over ``WALL_TRUST_FIT_S``): in a corridor people
walk along it, and a few seconds of track are 10-25 deg off. Persons walking
abreast (``ABREAST_ALONG_M``, no room for the robot between them) are passed
as one, beyond the outermost on the side taken. The lane's room is looked
at again each scan until they are ``RECHECK_UNTIL_M`` away (the side kept).
Each step aside, each wait and each return to the way is an event
(``step_aside``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Callable, Optional

import numpy as np

from beastbt.blackboard.types import COST_INSCRIBED, COST_LETHAL, LaserScan, LocalCostmap
from beastbt.devices.lidar_scan import LidarMounting
from beastbt.navigation.local_costmap import cost_at
from beastbt.navigation.local_planner import DwaPlanner, Limits, LocalPlannerConfig, PlanResult, arcs

JUMP_M = 0.2
"""Neighbouring returns farther apart than this are on different things (m)."""
MIN_POINTS = 3
"""A blob has at least this many returns."""
MAX_WIDTH_M = 0.8
"""A blob is at most this wide, end to end (m): a person seen from any side; a wall is wider."""
FOREGROUND_M = 0.15
"""The returns just beside a blob lie at least this much farther than its ends (or return nothing) (m)."""
GATE_M = 0.6
"""A blob belongs to a track when it lies within this of the track's predicted centre (m)."""
HISTORY_S = 2.0
"""A track's velocity is fitted to its centres of the last this long (s)."""
LOST_S = 0.6
"""A track not seen for this long is dropped (s)."""
CONFIRM_S = 1.0
"""A track is a walking person once followed this long at walking speed (s): long enough for its direction."""
HEAD_ON_COS = 0.5
"""A person comes toward the robot's way when its velocity is within 60 deg (cos 0.5) of head-on."""
ROOM_MARGIN_M = 0.05
"""A side has room when the robot's place there, and this much farther out, is below the inscribed cost (m)."""
ROOM_STEP_M = 0.05
"""A side without room for the full passing distance is tried this much closer, down to half the clearance (m)."""
ROOM_AHEAD_M = (0.4, 0.8, 1.2, 1.6)
"""Where along the way (m ahead of the robot) the room on a side is looked for."""
STOPPED_S = 1.0
"""A person being passed who has stood (below walking speed) this long is no longer passed (s)."""
REIDENTIFY_M = 0.8
"""A person being passed whose track was lost is the new track within this of where they should be (m)."""
LOST_GIVE_UP_S = 2.0
"""A person being passed who has not been seen for this long is taken to have gone (s)."""
TURN_S = 1.0
"""Stepping aside: the time to turn toward the lane and back, roughly (s)."""
LATERAL_FRACTION = 0.75
"""Stepping aside: the part of the speed that carries the robot sideways (a turn of about 50 deg)."""
BESIDE_BEFORE_S = 1.0
"""Stepping aside: a side counts as in time when the robot is there this long before the person would meet it (s)."""
LANE_APPROACH_M = 0.6
"""Until the robot is beside the person's line it steers for the lane this far ahead (m)."""
LANE_FAST_M = 0.15
"""... and while it is more than this from the lane, at the robot's top speed (m)."""
LANE_TOLERANCE_M = 0.05
"""... within this of the lane it follows the way's carrot moved aside (m)."""
PERSON_RADIUS_MIN_M = 0.15
"""A blob narrower than this is taken to be a person of this radius (m)."""
PERSON_RADIUS_MAX_M = 0.35
"""... and a wider one of at most this (m)."""
PASS_RADIUS_MIN_M = 0.25
"""A person being passed is taken to be at least this wide in radius (m, shoulders): from 8-10 m away the LiDAR's few
beams on them span less than their width (0.8 deg steps: 0.14 m at 10 m), and a lane planned for the blob's width there
was too close to them (a 2 m corridor: the robot chose a side with no room for them)."""
PASS_MIN_CLEARANCE_M = 0.05
"""A side without room for ``pass_clearance_m`` is tried with less, down to this between the footprint and the person
(m): in a corridor about 1.5 m wide a person on its middle leaves the robot no more, and it is that or be walked into.
A side with at least half the clearance is taken before one with less, even against ``pass_side``."""
KEEP_SIDE_CLEARANCE_M = 0.02
"""Once passing, the lane is moved to where the side chosen has room for this much between footprint and person (m),
less than a new side needs: the room as the costmap shows it flickers by a cell."""
RECHECK_UNTIL_M = 2.5
"""The room on the side of a pass is looked at again with each scan until the person is this close (m): nearer, their
own returns lie in the lane's inflation and the side would be given up for the person themself."""
LANE_HISTORY_S = 6.0
"""The lanes of a pass run along the straight line fitted to the person's centres of the last this long (s)."""
TIGHT_STOP_S = 3.0
"""In a lane with less than half of ``pass_clearance_m`` (tight), the robot stops once the person would meet it within
this (s) and waits there until they are by: a robot driving on beside them that close would have no room to steer."""
ABREAST_ALONG_M = 1.5
"""Persons walking at the robot within this of each other along its way are abreast (m) ...
... when the gap between them (beyond their radii) is narrower than the footprint's width and ``pass_clearance_m``:
they are passed as one, beyond the outermost on the side taken (two people side by side in a 2.8 m corridor, passed
beyond the nearer one alone: the robot stood in the other's way)."""
WALL_SNAP_DEG = 25.0
"""A person's walk fitted within this of the walls' direction (:func:`wall_direction`) is taken to be along the walls
(deg): in a corridor people walk along it, and the direction fitted to a track's first 2 s was 10-25 deg off 8 m away,
which put their line 2 m beside where they walked (a 2 m corridor: the robot chose the side they were on)."""
WALL_KEEP_DEG = 10.0
"""... and once the person's line is fitted over :data:`WALL_TRUST_FIT_S` or more, only within this (deg): a person
who truly walks across a corridor's line, or beside a lone wall at a slant, keeps their own direction."""
WALL_TRUST_FIT_S = 3.0
"""A person's line fitted over at least this long (s) is trusted before the walls beyond :data:`WALL_KEEP_DEG`."""
WALL_MIN_M = 1.5
"""A wall is a straight line of lethal cells at least this long in the local costmap (m)."""
WALL_STEP_DEG = 1.0
"""The directions tried for a wall, this far apart (deg)."""
FREE_AGE_S = (0.8, 2.0)
"""A walking person stands where the scans of this long ago (s, youngest and oldest) saw free space."""
FREE_MARGIN_M = 0.05
"""... the beam toward a place and those either side saw it free when they reached this much beyond it (m), or
returned nothing."""
FREE_SHARE = 0.5
"""... in at least this share of those scans: a wall's corner or end, seen through in none, is never a person."""
FREE_LOOKS = 3
"""... and at least this many of them looked its way (the first scans of a run say nothing yet)."""


def blobs(scan: LaserScan, mounting: LidarMounting, max_range_m: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """The blobs of ``scan`` as the module docstring says: (k, 3) centre x, y in base_link (m) and half-width (m),
    and each blob's beams (indices into the scan)."""
    r = np.asarray(scan.ranges_m, dtype=float)
    a = np.asarray(scan.angles_rad, dtype=float)
    n = len(r)
    if n < MIN_POINTS:
        return np.zeros((0, 3)), []
    ok = np.isfinite(r)
    a = a + math.radians(mounting.yaw_deg)
    x = np.where(ok, r * np.cos(a), np.nan) + mounting.x_m
    y = np.where(ok, r * np.sin(a), np.nan) + mounting.y_m
    gap = np.hypot(np.diff(x, append=x[:1]), np.diff(y, append=y[:1]))  # point i to i+1, the last to the first
    cut = ~(gap <= JUMP_M)  # NaN (no return) cuts too
    if not cut.any():
        return np.zeros((0, 3)), []  # one unbroken ring: walls all round
    # Start after a cut, so that a run across the scan's seam is one run.
    start = int(np.flatnonzero(cut)[0]) + 1
    order = np.roll(np.arange(n), -start)
    out = []
    beams = []
    ends = np.flatnonzero(cut[order])  # each run ends where a cut follows it; the last one at n - 1
    begin = 0
    for j in ends:
        idx = order[begin:j + 1]  # a run, in the order measured
        i = j + 1
        begin = i
        if len(idx) < MIN_POINTS or not ok[idx].all():
            continue
        px, py = x[idx], y[idx]
        width = math.hypot(px[-1] - px[0], py[-1] - py[0])
        if width > MAX_WIDTH_M:
            continue
        before, after = r[order[(i - len(idx) - 1) % n]], r[order[i % n]]
        near_end = min(r[idx[0]], r[idx[-1]])
        if not ((not np.isfinite(before) or before > near_end + FOREGROUND_M)
                and (not np.isfinite(after) or after > near_end + FOREGROUND_M)):
            continue
        cx, cy = float(px.mean()), float(py.mean())
        d = math.hypot(cx - mounting.x_m, cy - mounting.y_m)
        if d > max_range_m or d < 1e-6:
            continue
        half = 0.5 * width
        push = 0.6 * min(max(half, PERSON_RADIUS_MIN_M), PERSON_RADIUS_MAX_M)
        cx += push * (cx - mounting.x_m) / d
        cy += push * (cy - mounting.y_m) / d
        out.append((cx, cy, half))
        beams.append(idx)
    return np.array(out, dtype=float).reshape(-1, 3), beams


@dataclass
class Track:
    """One thing followed across scans: its centres ``(t s, x m, y m)`` (odom) of the last ``HISTORY_S``, its
    half-width (m), and its velocity ``vx``, ``vy`` (m/s, odom) fitted to them."""

    id: int
    history: deque = field(default_factory=deque)
    half_width_m: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    first_s: float = 0.0
    walking_since_s: Optional[float] = None
    widest_m: float = 0.0
    """The largest half-width seen (m): a person seen closer shows more of their width, never less of it."""
    fit_x: float = 0.0
    fit_y: float = 0.0
    """Where the straight line fitted to the centres of the last ``HISTORY_S`` puts it at the newest scan (m, odom):
    steadier than the newest centre, which wanders 0.2-0.4 m across from one scan to the next 10 m away (a few
    beams on the person, a robot turning)."""

    @property
    def last(self) -> tuple[float, float, float]:
        """The newest ``(t, x, y)``."""
        return self.history[-1]

    @property
    def speed_mps(self) -> float:
        """The fitted speed (m/s)."""
        return math.hypot(self.vx, self.vy)

    def predict(self, t_s: float) -> tuple[float, float]:
        """Where it will be at ``t_s`` at its fitted velocity (m, odom)."""
        t, x, y = self.last
        return x + self.vx * (t_s - t), y + self.vy * (t_s - t)

    def add(self, t_s: float, x: float, y: float, half_width_m: float) -> None:
        """A new centre seen at ``t_s``; the velocity refitted over the last ``HISTORY_S``."""
        h = self.history
        h.append((t_s, x, y))
        while len(h) > 2 and h[0][0] < t_s - HISTORY_S:
            h.popleft()
        self.half_width_m = half_width_m
        self.widest_m = max(self.widest_m, half_width_m)
        self.fit_x, self.fit_y = x, y
        if len(h) >= 3:
            line = _least_squares(np.array(h))
            if line is not None:
                self.fit_x, self.fit_y, self.vx, self.vy = line

    @property
    def radius_m(self) -> float:
        """The person's radius as the blob shows it (m), within the bounds people have."""
        return min(max(self.half_width_m, PERSON_RADIUS_MIN_M), PERSON_RADIUS_MAX_M)

    @property
    def pass_radius_m(self) -> float:
        """The radius a pass keeps clear of (m): the widest the blob has been, at least :data:`PASS_RADIUS_MIN_M`,
        at most :data:`PERSON_RADIUS_MAX_M`."""
        return min(max(self.widest_m, PASS_RADIUS_MIN_M), PERSON_RADIUS_MAX_M)


class PersonTracker:
    """Tracks of what moves in the scans (module docstring); ``min_speed_mps`` makes a track a walking person."""

    def __init__(self, min_speed_mps: float = 0.3, max_range_m: float = 8.0) -> None:
        self.min_speed_mps = min_speed_mps
        self.max_range_m = max_range_m
        self.tracks: list[Track] = []
        self.stamp_s = -math.inf
        """The newest scan's stamp (s)."""
        self.walking_beams: list[np.ndarray] = []
        """The beams (indices into the newest scan) that hit walking persons."""
        self._next_id = 1
        self._past: deque[tuple[float, float, float, np.ndarray, np.ndarray]] = deque()
        """The scans of the last ``FREE_AGE_S[1]``: (stamp s, LiDAR x m, y m in odom, each beam's bearing rad in odom
        at its own time, ranges m)."""

    def update(self, scan: LaserScan, mounting: LidarMounting,
               pose_at: Callable[[float], Optional[tuple[float, float, float]]]) -> None:
        """Take a scan; ``pose_at(t)`` is the odom pose (x m, y m, yaw rad) of base_link at time ``t`` (s).

        Each blob is placed with the pose at the time its beams were measured (the revolution's beams come in
        order over ``scan_time_s`` up to the stamp): a robot turning at 0.4 rad/s would otherwise throw a person
        10 m away 0.4 m sideways between one scan and the next, and their direction with it."""
        t = scan.stamp_s
        self.stamp_s = t
        found, beams = blobs(scan, mounting, self.max_range_m)
        n = max(len(scan.ranges_m), 1)
        period = scan.scan_time_s if math.isfinite(scan.scan_time_s) else 0.0
        centres = np.zeros((len(found), 3))
        for k, idx in enumerate(beams):
            at = pose_at(t - period * (1.0 - (float(idx.mean()) + 0.5) / n)) or pose_at(t)
            assert at is not None
            c, s = math.cos(at[2]), math.sin(at[2])
            centres[k] = (at[0] + c * found[k, 0] - s * found[k, 1], at[1] + s * found[k, 0] + c * found[k, 1],
                          found[k, 2])
        matched = self.add_centres(t, centres, lambda which: self.seen_free(t, centres[which, :2]))
        self._remember(scan, mounting, pose_at)
        walking = {tr.id for tr in self.walking()}
        self.walking_beams = [beams[bi] for bi, tid in matched.items() if tid in walking]

    def _remember(self, scan: LaserScan, mounting: LidarMounting,
                  pose_at: Callable[[float], Optional[tuple[float, float, float]]]) -> None:
        """Keep ``scan`` (its beams' bearings in odom at their own times) for :meth:`seen_free`."""
        t = scan.stamp_s
        end = pose_at(t)
        if end is None:
            return
        period = scan.scan_time_s if math.isfinite(scan.scan_time_s) else 0.0
        start = pose_at(t - period) or end
        n = max(len(scan.ranges_m), 1)
        frac = (np.arange(len(scan.ranges_m)) + 0.5) / n
        turn = (end[2] - start[2] + math.pi) % (2.0 * math.pi) - math.pi
        yaw = end[2] - turn * (1.0 - frac)
        c, s = math.cos(end[2]), math.sin(end[2])
        ox, oy = end[0] + c * mounting.x_m - s * mounting.y_m, end[1] + s * mounting.x_m + c * mounting.y_m
        bearings = np.asarray(scan.angles_rad, dtype=float) + math.radians(mounting.yaw_deg) + yaw
        self._past.append((t, ox, oy, bearings, np.asarray(scan.ranges_m, dtype=float)))
        while self._past and self._past[0][0] < t - FREE_AGE_S[1] - 1e-9:
            self._past.popleft()

    def seen_free(self, t_s: float, xy: np.ndarray) -> np.ndarray:
        """For each point ``xy`` ((k, 2) m, odom): whether the scans of ``FREE_AGE_S`` before ``t_s`` saw it free
        (the beam toward it reached ``FREE_MARGIN_M`` beyond it, or returned nothing) in ``FREE_SHARE`` of those that
        looked its way. A person walks into space that was free; a wall's corner or end was never seen through
        (and one just come into sight was not seen at all), however its blob's centre wanders as the robot moves."""
        out = np.zeros(len(xy), dtype=bool)
        if len(xy) == 0:
            return out
        free = np.zeros(len(xy))
        looked = np.zeros(len(xy))
        for stamp, ox, oy, bearings, ranges in self._past:
            n = len(bearings)
            if not (t_s - FREE_AGE_S[1] - 1e-9 <= stamp <= t_s - FREE_AGE_S[0] + 1e-9) or n < 2:
                continue
            dx, dy = xy[:, 0] - ox, xy[:, 1] - oy
            d = np.hypot(dx, dy)
            off = np.abs((bearings[None, :] - np.arctan2(dy, dx)[:, None] + math.pi) % (2.0 * math.pi) - math.pi)
            i = np.argmin(off, axis=1)
            # No beam that way (a LiDAR with a blind sector), or out of range: that scan says nothing.
            seen = (off[np.arange(len(xy)), i] <= 1.5 * 2.0 * math.pi / n) & (d <= self.max_range_m)
            # The nearest beam and those either side: a beam slipping past a wall's corner is not seen through.
            near = ranges[(i[:, None] + np.arange(-1, 2)[None, :]) % n]
            through = (~np.isfinite(near) | (near > d[:, None] + FREE_MARGIN_M)).all(axis=1)
            looked += seen
            free += seen & through
        return (looked >= FREE_LOOKS) & (free >= FREE_SHARE * looked)

    def add_centres(self, t_s: float, centres: np.ndarray,
                    free: Optional[Callable[[list[int]], np.ndarray]] = None) -> dict[int, int]:
        """Match blobs seen at ``t_s`` ((k, 3): x m, y m in odom, half-width m) to the tracks: nearest first within
        ``GATE_M`` of each track's prediction; the rest start tracks; tracks unseen for ``LOST_S`` go. Returns each
        blob's track id. ``free(blobs)`` (:meth:`seen_free` of those blob indices, asked only for the blobs of tracks
        moving at walking speed) says which stand where earlier scans saw free space: only those walk (None: all)."""
        self.tracks = [tr for tr in self.tracks if t_s - tr.last[0] <= LOST_S]
        pairs = []
        for ti, tr in enumerate(self.tracks):
            px, py = tr.predict(t_s)
            for bi in range(len(centres)):
                d = math.hypot(centres[bi, 0] - px, centres[bi, 1] - py)
                if d <= GATE_M:
                    pairs.append((d, ti, bi))
        pairs.sort()
        used_t: set[int] = set()
        used_b: set[int] = set()
        matched: dict[int, int] = {}
        for _, ti, bi in pairs:
            if ti in used_t or bi in used_b:
                continue
            used_t.add(ti)
            used_b.add(bi)
            matched[bi] = self.tracks[ti].id
            self.tracks[ti].add(t_s, float(centres[bi, 0]), float(centres[bi, 1]), float(centres[bi, 2]))
        for bi in range(len(centres)):
            if bi not in used_b:
                tr = Track(self._next_id, first_s=t_s)
                self._next_id += 1
                tr.add(t_s, float(centres[bi, 0]), float(centres[bi, 1]), float(centres[bi, 2]))
                self.tracks.append(tr)
                matched[bi] = tr.id
        moving = {tr.id for tr in self.tracks
                  if tr.last[0] == t_s and len(tr.history) >= 3 and tr.speed_mps >= self.min_speed_mps}
        which = [bi for bi, tid in matched.items() if tid in moving]
        if free is not None and which:
            moving = {matched[bi] for bi, ok in zip(which, free(which)) if ok}
        for tr in self.tracks:
            if tr.id in moving:
                if tr.walking_since_s is None:
                    tr.walking_since_s = t_s
            elif tr.last[0] == t_s:
                tr.walking_since_s = None
        return matched

    def walking(self) -> list[Track]:
        """The tracks that are walking persons now (seen in the newest scan, walking for ``CONFIRM_S``)."""
        return [tr for tr in self.tracks if tr.walking_since_s is not None and tr.last[0] >= self.stamp_s - 1e-9
                and self.stamp_s - tr.walking_since_s >= CONFIRM_S - 1e-9]

    def without_walkers(self, scan: LaserScan) -> LaserScan:
        """``scan`` (the newest) with the beams that hit walking persons as no return (NaN): what the global
        costmap marks. A person walking at the robot hides where they walked from the beams; without this their
        trail stays marked behind them until they have passed, and the global planner plans round it."""
        if not self.walking_beams:
            return scan
        ranges = np.array(scan.ranges_m, dtype=float, copy=True)
        ranges[np.concatenate(self.walking_beams)] = np.nan
        return replace(scan, ranges_m=ranges)

    def clear(self) -> None:
        """Forget every track (a recovery cleared the costmaps)."""
        self.tracks = []
        self.walking_beams = []
        self._past.clear()


@dataclass
class Pass:
    """A person being passed: the track, the side (+1 the robot's left, -1 its right, of the way ``ux``, ``uy``
    fixed when it began), the passing distance (m), and whether the robot waits instead (no room either side)."""

    track_id: int
    side: int
    ux: float
    uy: float
    distance_m: float
    waiting: bool
    began_s: float
    px: float = 0.0
    py: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    seen_s: float = 0.0
    still_s: float = 0.0
    checked_s: float = 0.0
    coming: int = 1
    """+1: the person walks at the robot (head-on); -1: they catch it up from behind (the lanes then run the
    robot's way, so that its right is the right)."""
    full_m: float = 0.0
    """The passing distance with the whole ``pass_clearance_m`` (m); ``distance_m`` is less where the walls leave
    less room."""
    tight_m: float = 0.0
    """Below this passing distance (m; half the clearance) the lane is tight: the robot waits in it for the person."""
    rechecked_s: float = -math.inf
    """The scan stamp (s) the side's room was last looked at again."""
    group: list = field(default_factory=list)
    """The persons walking abreast (:meth:`PassingPlanner._abreast`, tracks), the first the one met first; the pass
    keeps beside the outermost on its side."""
    samples: deque = field(default_factory=deque)
    """The person's centres ``(t s, x m, y m)`` (odom) of the last :data:`LANE_HISTORY_S`, across re-identified
    tracks: the lanes' line is fitted to them."""

    @property
    def tight(self) -> bool:
        """Whether the lane leaves less than half the clearance (the robot stops in it while the person goes by)."""
        return self.distance_m < self.tight_m - 1e-9

    @property
    def speed_mps(self) -> float:
        """The person's speed (m/s)."""
        return math.hypot(self.vx, self.vy)

    @property
    def normal(self) -> tuple[float, float]:
        """The unit vector toward the side passed on (m, odom)."""
        return -self.uy * self.side, self.ux * self.side


EventSink = Callable[[str, str], None]


class PassingPlanner(DwaPlanner):
    """:class:`DwaPlanner` that passes walking persons on ``config.pass_side`` (module docstring).

    ``tracker`` is fed by the :class:`~beastbt.navigation.local_navigator.LocalNavigator` with every new scan;
    ``events`` (kind, text) is where the step asides are told (None: nowhere).
    """

    def __init__(self, config: LocalPlannerConfig, limits: Limits, tracker: PersonTracker,
                 footprint_radius_m: float) -> None:
        super().__init__(config, limits)
        self.tracker = tracker
        self.footprint_radius_m = footprint_radius_m
        self.events: Optional[EventSink] = None
        self.passing: Optional[Pass] = None
        self.step_asides = 0
        """Step asides so far (each an event)."""
        self.waits = 0
        """Times the robot stopped for a person, with no room on either side."""
        self.why_not_preferred = ""
        """Why the last pass was not on ``pass_side`` (for its event)."""
        self._walls: dict[tuple, Optional[tuple[float, float]]] = {}
        """:func:`wall_direction` by (costmap stamp, direction, tolerance), of the newest costmaps."""

    def _tell(self, text: str) -> None:
        if self.events is not None:
            self.events("step_aside", text)

    def plan(self, costmap: Optional[LocalCostmap], pose: tuple[float, float, float], last: tuple[float, float],
             preferred: tuple[float, float], carrot_xy: tuple[float, float], max_speed_mps: float,
             max_turn_rps: float, target_xy: Optional[tuple[float, float]] = None, keep_planning: bool = False
             ) -> PlanResult:
        """As :meth:`DwaPlanner.plan`, but with a walking person to pass the carrot and the goal move aside, the
        lane is steered for until the robot is in it (at the top speed while it is more than ``LANE_FAST_M`` off),
        and with no room either side the robot stops."""
        cfg = self.config
        if not cfg.step_aside or costmap is None:
            if self.passing is not None:
                self.passing = None
            return super().plan(costmap, pose, last, preferred, carrot_xy, max_speed_mps, max_turn_rps, target_xy,
                                keep_planning)
        p = self._update_pass(costmap, pose, last, carrot_xy, max_speed_mps)
        if p is None:
            return super().plan(costmap, pose, last, preferred, carrot_xy, max_speed_mps, max_turn_rps, target_xy,
                                keep_planning)
        if p.waiting:
            return PlanResult(0.0, 0.0, np.array([[pose[0], pose[1]]]), False, True, 0, 0)
        carrot = self._aside(p, carrot_xy)
        target = self._aside(p, target_xy if target_xy is not None else carrot_xy)
        nx, ny = p.normal
        need = p.distance_m - ((pose[0] - p.px) * nx + (pose[1] - p.py) * ny)
        # A tight lane (a narrow corridor): once the person is near, the robot stands in it and lets them by; one
        # driving on that close beside them has no room to steer.
        apart = p.coming * ((p.px - pose[0]) * p.ux + (p.py - pose[1]) * p.uy)
        closing = p.speed_mps + p.coming * max(0.0, last[0])
        hold = p.tight and apart < TIGHT_STOP_S * max(closing, 1e-3)
        if hold and need <= LANE_TOLERANCE_M:
            return PlanResult(0.0, 0.0, np.array([[pose[0], pose[1]]]), False, True, 0, 0)
        if need > LANE_TOLERANCE_M:
            # Not beside the person's line yet: steer for the lane just ahead, a turn of 30-50 deg, so that the robot
            # moves over in a few seconds (the carrot well ahead would make it a slow drift).
            carrot = (pose[0] + LANE_APPROACH_M * p.ux + need * nx, pose[1] + LANE_APPROACH_M * p.uy + need * ny)
        pref = pursue(pose, carrot, max_speed_mps, max_turn_rps)
        if need > LANE_FAST_M:
            # Getting out of a person's way is done at the robot's top speed (the step's own speed may be slower).
            pref = pursue(pose, carrot, max(max_speed_mps, self.limits.max_speed_mps), max_turn_rps)
        # Moving over, and in the lane: the pursuit of the lane as it is when its arc stays clear of what the footprint
        # would touch (the planner's scores would trade the move for keeping off the walls' inflation, and be late;
        # in a lane beside a wall they drew the robot back toward the middle, into the person's way).
        x, y = arcs(pose, np.array([pref[0]]), np.array([pref[1]]), self.times)
        if (cost_at(costmap, x[0], y[0]) < COST_INSCRIBED).all():
            return PlanResult(pref[0], pref[1], np.column_stack((x[0], y[0])), True, False, 1, 1)
        if hold and need <= LANE_FAST_M:
            # Nearly in the tight lane and no clear arc to the rest of it: stand here.
            return PlanResult(0.0, 0.0, np.array([[pose[0], pose[1]]]), False, True, 0, 0)
        return super().plan(costmap, pose, last, pref, carrot, max_speed_mps, max_turn_rps, target, True)

    # -- the pass ---------------------------------------------------------------------------------------------
    def _aside(self, p: Pass, xy: tuple[float, float]) -> tuple[float, float]:
        """``xy`` (odom, m) moved along the pass's normal until it lies the passing distance beyond the person's
        line (unchanged where it already does)."""
        nx, ny = p.normal
        lateral = (xy[0] - p.px) * nx + (xy[1] - p.py) * ny
        shift = max(0.0, p.distance_m - lateral)
        return xy[0] + shift * nx, xy[1] + shift * ny

    def _update_pass(self, costmap: LocalCostmap, pose: tuple[float, float, float], last: tuple[float, float],
                     carrot_xy: tuple[float, float], max_speed_mps: float) -> Optional[Pass]:
        """The pass under way, a new one, or None; ends a pass once its person is behind the robot or gone."""
        cfg = self.config
        now = self.tracker.stamp_s
        rx, ry = pose[0], pose[1]
        p = self.passing
        if p is not None:
            tr = next((t for t in self.tracker.tracks if t.id == p.track_id), None)
            if tr is None:
                # Lost for a scan or two and found again as a new track: the walking track nearest where the person
                # should be now is the same person.
                ex, ey = p.px + p.vx * (now - p.seen_s), p.py + p.vy * (now - p.seen_s)
                near = [(math.hypot(t.last[1] - ex, t.last[2] - ey), t.id, t) for t in self.tracker.tracks
                        if t.last[0] == now and len(t.history) >= 2]
                near = [n for n in near if n[0] <= REIDENTIFY_M]
                if near:
                    tr = min(near)[2]
                    p.track_id = tr.id
            if tr is not None:
                p.px, p.py = tr.fit_x, tr.fit_y
                p.vx, p.vy, p.seen_s = tr.vx, tr.vy, tr.last[0]
                if tr.last[0] > p.samples[-1][0]:
                    p.samples.append(tr.last)
                while p.samples[0][0] < now - LANE_HISTORY_S:
                    p.samples.popleft()
                line = fit_line(p.samples)
                if line is not None and math.hypot(line[2], line[3]) >= self.tracker.min_speed_mps:
                    # The person's line fitted to all the pass has seen of them: its direction from a track's 2 s
                    # was 10-25 deg off 8 m away (and more on a track begun again), a metre off where the robot was.
                    # Along the walls when it is near their direction (WALL_SNAP_DEG; WALL_KEEP_DEG once fitted long).
                    p.px, p.py = line[0], line[1]
                    s = math.hypot(line[2], line[3]) * -p.coming
                    span = p.samples[-1][0] - p.samples[0][0]
                    p.ux, p.uy = self._along_walls(costmap, line[2] / s, line[3] / s,
                                                   WALL_SNAP_DEG if span < WALL_TRUST_FIT_S else WALL_KEEP_DEG)
                px, py = p.px, p.py
            else:  # out of sight a moment (merged with a wall, or in the robot's shadow): carried on at its speed
                px, py = p.px + p.vx * (now - p.seen_s), p.py + p.vy * (now - p.seen_s)
            # Passed: a person met head-on is behind the robot, one who caught it up is ahead of it.
            behind = p.coming * ((px - rx) * p.ux + (py - ry) * p.uy) < -(p.distance_m + 0.1)
            gone = tr is None and now - p.seen_s > LOST_GIVE_UP_S
            if tr is not None and tr.walking_since_s is None and tr.last[0] == now:
                p.still_s += now - p.checked_s
            elif tr is not None:
                p.still_s = 0.0
            p.checked_s = now
            stopped = p.still_s >= STOPPED_S  # a person who stands is an obstacle like any other
            if behind or gone or stopped:
                self.passing = None
                what = "passed" if behind else "stopped walking" if stopped else "went out of sight"
                self._tell(f"back on the way: the person {what} after {now - p.began_s:.1f} s "
                           f"{'waiting' if p.waiting else 'aside'}")
                return None
            apart = p.coming * ((px - rx) * p.ux + (py - ry) * p.uy)
            if not p.waiting and tr is not None and now > p.rechecked_s and apart > RECHECK_UNTIL_M:
                tr = self._regroup(p, tr)
                self._recheck(costmap, pose, p, tr)
            if p.waiting:  # no room a moment ago: look again (the person has come on, the robot may have room now)
                apart = abs((px - rx) * p.ux + (py - ry) * p.uy)
                closing = p.speed_mps + p.coming * max(0.0, last[0])
                side = self._free_side(costmap, pose, p, apart / max(closing, 1e-3), max_speed_mps)
                if side is not None:
                    p.side, p.waiting = side, False
                    self.step_asides += 1
                    self._tell(f"stepping aside to the {side_name(side)} now: room there for the person to pass")
            return p
        ux, uy = carrot_xy[0] - rx, carrot_xy[1] - ry
        d = math.hypot(ux, uy)
        if d < 1e-3:
            ux, uy = math.cos(pose[2]), math.sin(pose[2])
        else:
            ux, uy = ux / d, uy / d
        best = None
        heading: list[tuple[Track, float, int]] = []  # every person walking at the robot in time: (track, ahead, coming)
        for tr in self.tracker.walking():
            px, py = tr.fit_x, tr.fit_y
            ahead = (px - rx) * ux + (py - ry) * uy
            along_v = tr.vx * ux + tr.vy * uy
            if ahead > 0.0 and along_v <= -HEAD_ON_COS * tr.speed_mps:
                coming, closing = 1, -along_v + max(0.0, last[0])  # walking at the robot
            elif ahead < 0.0 and along_v >= HEAD_ON_COS * tr.speed_mps:
                coming, closing = -1, along_v - max(0.0, last[0])  # catching it up from behind
                if closing < self.tracker.min_speed_mps:
                    continue
            else:
                continue  # crossing the robot's way, or going away from it
            t_meet = abs(ahead) / max(closing, 1e-3)
            if t_meet > cfg.pass_react_time_s:
                continue
            heading.append((tr, ahead, coming))
            distance = self.footprint_radius_m + tr.pass_radius_m + cfg.pass_clearance_m
            # The person's offset from the robot's line (to its left) when they meet, walking along the walls when
            # their fitted walk is near the walls' direction.
            wx, wy = self._along_walls(costmap, tr.vx / tr.speed_mps, tr.vy / tr.speed_mps, WALL_SNAP_DEG)
            vx, vy = wx * tr.speed_mps, wy * tr.speed_mps
            lateral = ((px + vx * t_meet - rx) * -uy + (py + vy * t_meet - ry) * ux)
            if abs(lateral) >= distance:
                continue  # their lines pass far enough apart already
            if best is None or t_meet < best[0]:
                best = (t_meet, tr, distance, ahead, coming)
        if best is None:
            return None
        t_meet, tr, distance, ahead, coming = best
        # The lanes run along the person's line: the robot keeps beside it however its own way bends.
        lx, ly = self._along_walls(costmap, *lane_direction(tr, coming), WALL_SNAP_DEG)
        p = Pass(tr.id, -1 if cfg.pass_side == "right" else 1, lx, ly, distance, False, now,
                 tr.fit_x, tr.fit_y, tr.vx, tr.vy, tr.last[0], checked_s=now, coming=coming,
                 full_m=distance, tight_m=distance - 0.5 * cfg.pass_clearance_m, rechecked_s=now,
                 samples=deque(tr.history))
        p.group = self._abreast(tr, ahead, coming, lx, ly, heading)
        side = self._free_side(costmap, pose, p, t_meet, max_speed_mps)
        if len(p.group) > 1:
            self._follow(p, self._outermost(p, side if side is not None else p.side))
        what = (f"a person {ahead:.1f} m ahead walking at the robot at {tr.speed_mps:.1f} m/s" if coming > 0 else
                f"a person {-ahead:.1f} m behind catching the robot up at {tr.speed_mps:.1f} m/s")
        if side is None:
            p.waiting = True
            self.waits += 1
            self._tell(f"no room to step aside for {what}: stopping to let them pass")
        else:
            p.side = side
            self.step_asides += 1
            preferred = "" if side == (-1 if cfg.pass_side == "right" else 1) else \
                f" ({self.why_not_preferred} on the {cfg.pass_side})"
            self._tell(f"stepping aside to the {side_name(side)}{preferred} for {what}")
        self.passing = p
        return p

    def _abreast(self, tr: Track, ahead: float, coming: int, lx: float, ly: float,
                 heading: list[tuple[Track, float, int]]) -> list[Track]:
        """``tr`` and the persons walking abreast of them (each a member of ``heading``, coming the same way, within
        :data:`ABREAST_ALONG_M` of them along the lanes and with no room for the robot between them and a member
        already found): passed as one, beyond the outermost on the side taken."""
        gap_m = 2.0 * self.footprint_radius_m + self.config.pass_clearance_m
        group = [tr]
        others = [o for o, a, c in heading if c == coming and o.id != tr.id and abs(a - ahead) <= ABREAST_ALONG_M]
        grew = True
        while grew:  # joined to any member already found, until no one more joins
            joined = [o for o in others if any(
                abs((o.fit_x - m.fit_x) * -ly + (o.fit_y - m.fit_y) * lx) < o.pass_radius_m + m.pass_radius_m + gap_m
                for m in group)]
            group += joined
            others = [o for o in others if all(o is not j for j in joined)]
            grew = bool(joined)
        return group

    def _regroup(self, p: Pass, tr: Track) -> Track:
        """The pass's persons abreast again (one beside the person passed may be confirmed walking a scan or two
        later): when one of them is farther toward the pass's side, the pass keeps beside them from now on; the
        person kept beside (a track)."""
        now = self.tracker.stamp_s
        heading = []
        for o in self.tracker.walking():
            if o.last[0] != now:
                continue
            along_v = o.vx * p.ux + o.vy * p.uy  # the lanes run the robot's way
            if p.coming * along_v <= -HEAD_ON_COS * o.speed_mps:
                heading.append((o, (o.fit_x - tr.fit_x) * p.ux + (o.fit_y - tr.fit_y) * p.uy, p.coming))
        if not any(o.id != tr.id for o, _, _ in heading):
            return tr
        p.group = self._abreast(tr, 0.0, p.coming, p.ux, p.uy, heading)
        outer = self._outermost(p, p.side)
        if outer.id == tr.id:
            return tr
        self._follow(p, outer)
        return outer

    @staticmethod
    def _outermost(p: Pass, side: int) -> Track:
        """The member of ``p.group`` farthest toward ``side`` of the lanes (+1 left, -1 right)."""
        return max(p.group, key=lambda t: side * ((t.fit_x - p.group[0].fit_x) * -p.uy
                                                  + (t.fit_y - p.group[0].fit_y) * p.ux))

    @staticmethod
    def _follow(p: Pass, tr: Track) -> None:
        """Make ``tr`` the person the pass keeps beside (their place, walk and centres)."""
        p.track_id = tr.id
        p.px, p.py, p.vx, p.vy, p.seen_s = tr.fit_x, tr.fit_y, tr.vx, tr.vy, tr.last[0]
        p.samples = deque(tr.history)

    def _along_walls(self, costmap: LocalCostmap, ux: float, uy: float, within_deg: float) -> tuple[float, float]:
        """(``ux``, ``uy``) (a unit direction, odom), or the walls' direction when it lies within ``within_deg`` of it
        (:func:`wall_direction`; kept for each costmap: the walls are looked for once per costmap and direction)."""
        key = (costmap.stamp_s, round(math.degrees(math.atan2(uy, ux)) / WALL_STEP_DEG), within_deg)
        if key not in self._walls:
            if len(self._walls) > 16:
                self._walls.clear()
            self._walls[key] = wall_direction(costmap, ux, uy, within_deg)
        found = self._walls[key]
        return found if found is not None else (ux, uy)

    def _recheck(self, costmap: LocalCostmap, pose: tuple[float, float, float], p: Pass, tr: Track) -> None:
        """With each new scan while the person is still more than :data:`RECHECK_UNTIL_M` away: the passing distance
        again for the person's width as seen now (nearer, the blob shows more of it) and the room on the side chosen
        as the costmap shows it now (the walls ahead come into its range): the lane as far from the person as that
        side has room for. The side itself is kept: 8-10 m away the person's line is known to a few tenths of a metre
        only, and changing sides on it walked the robot back and forth across their way."""
        cfg = self.config
        p.rechecked_s = self.tracker.stamp_s
        full = self.footprint_radius_m + tr.pass_radius_m + cfg.pass_clearance_m
        p.full_m, p.tight_m = full, full - 0.5 * cfg.pass_clearance_m
        d = self._widest(costmap, pose, p, p.side, KEEP_SIDE_CLEARANCE_M)
        if d is not None:
            p.distance_m = d

    def _free_side(self, costmap: LocalCostmap, pose: tuple[float, float, float], p: Pass, t_meet_s: float,
                   speed_mps: float) -> Optional[int]:
        """The side to pass on (+1 left, -1 right), None when neither has room: ``pass_side`` when the costmap has
        room for the robot there and it can be there before the person (``t_meet_s`` from now, less
        :data:`BESIDE_BEFORE_S`, at ``speed_mps``), else the other side if that can; else the side with room that
        needs the shorter step (a robot already beside the person's line on the other side does not cut across
        their way to keep to its own). Sets ``p.distance_m`` to the chosen side's (:meth:`_widest`)."""
        first = -1 if self.config.pass_side == "right" else 1
        fast = max(speed_mps, self.limits.max_speed_mps)
        options = []
        for side in (first, -first):
            if len(p.group) > 1:
                self._follow(p, self._outermost(p, side))  # people abreast: passed beyond the one on that side
            d = self._widest(costmap, pose, p, side)
            if d is not None:
                p.distance_m = d
                shift = self._shift(pose, p, side)
                options.append((side, shift, TURN_S + shift / max(LATERAL_FRACTION * fast, 1e-3), d))
        p.distance_m = p.full_m
        self.why_not_preferred = "no room" if not options or options[0][0] != first else "no time to get there"
        if not options:
            return None
        in_time = [o for o in options if o[2] <= t_meet_s - BESIDE_BEFORE_S]
        # A side with room for half the clearance or more before a tight one (a person 0.3 m to the robot's right in a
        # 2 m corridor leaves the right side 0.05 m: the left is the way).
        roomy = [o for o in in_time if o[3] >= p.tight_m - 1e-9]
        chosen = roomy[0] if roomy else in_time[0] if in_time else min(options, key=lambda o: o[1])
        if chosen[0] != first and options[0][0] == first:
            self.why_not_preferred = "no time to get there" if options[0] not in in_time else "little room"
        p.distance_m = chosen[3]
        return chosen[0]

    def _widest(self, costmap: LocalCostmap, pose: tuple[float, float, float], p: Pass, side: int,
                clearance_m: float = PASS_MIN_CLEARANCE_M) -> Optional[float]:
        """The widest passing distance (m) that has room on ``side``: the full one (``p.full_m``), else in steps of
        :data:`ROOM_STEP_M` down to half the clearance with the robot's place :data:`ROOM_MARGIN_M` clear too, then
        on down to ``clearance_m`` between footprint and person with the place itself clear (a narrow corridor: the
        robot as far from the person as the walls let it be); None when there is none."""
        full = p.full_m
        half = p.tight_m
        least = full - self.config.pass_clearance_m + min(clearance_m, self.config.pass_clearance_m)
        d = full
        keep = p.distance_m
        try:
            while d >= least - 1e-9:
                p.distance_m = d
                if self._room(costmap, pose, p, side, self._shift(pose, p, side),
                              ROOM_MARGIN_M if d >= half - 1e-9 else 0.0):
                    return d
                d -= ROOM_STEP_M
            return None
        finally:
            p.distance_m = keep

    @staticmethod
    def _shift(pose: tuple[float, float, float], p: Pass, side: int) -> float:
        """How far (m) the robot must move toward ``side`` to be the passing distance beyond the person's line."""
        nx, ny = -p.uy * side, p.ux * side
        return max(0.0, p.distance_m - ((pose[0] - p.px) * nx + (pose[1] - p.py) * ny))

    def _room(self, costmap: LocalCostmap, pose: tuple[float, float, float], p: Pass, side: int, shift: float,
              margin_m: float = ROOM_MARGIN_M) -> bool:
        """Whether the robot fits ``shift`` (m) toward ``side`` (the passing distance beyond the person's line), along
        the way ahead: every point there, and ``margin_m`` beyond, below the inscribed cost."""
        nx, ny = -p.uy * side, p.ux * side
        rx, ry = pose[0], pose[1]
        xs, ys = [], []
        for a in ROOM_AHEAD_M:
            for extra in (0.0, margin_m):
                xs.append(rx + a * p.ux + (shift + extra) * nx)
                ys.append(ry + a * p.uy + (shift + extra) * ny)
        # The way there, just ahead, all across: the costmap marks a wall as a line of returns, and a lane beyond it
        # (a person's line misjudged by half a metre in a 1.5 m corridor) is "free" on the far side.
        for f in np.arange(ROOM_STEP_M, shift, ROOM_STEP_M):
            xs.append(rx + ROOM_AHEAD_M[0] * p.ux + f * nx)
            ys.append(ry + ROOM_AHEAD_M[0] * p.uy + f * ny)
        return bool((cost_at(costmap, np.array(xs), np.array(ys)) < COST_INSCRIBED).all())


def wall_direction(costmap: LocalCostmap, ux: float, uy: float, within_deg: float = WALL_SNAP_DEG
                   ) -> Optional[tuple[float, float]]:
    """The direction (unit, odom, the sign of ``ux``, ``uy``) of the longest straight line of lethal cells in
    ``costmap`` within ``within_deg`` of (``ux``, ``uy``), when it is at least :data:`WALL_MIN_M` long; else None. A
    Hough transform kept to those directions: each lethal cell votes, for each direction tried (every
    :data:`WALL_STEP_DEG`), for its offset across it in bins of 1.5 cells; the most votes win."""
    rows, cols = np.nonzero(costmap.cost == COST_LETHAL)
    res = costmap.resolution_m
    if len(rows) * res < WALL_MIN_M:
        return None
    x = costmap.origin_x_m + (cols + 0.5) * res
    y = costmap.origin_y_m + (rows + 0.5) * res
    base = math.atan2(uy, ux)
    angles = base + np.radians(np.arange(-within_deg, within_deg + 1e-9, WALL_STEP_DEG))
    across = np.outer(-np.sin(angles), x) + np.outer(np.cos(angles), y)  # (directions, cells) offsets, m
    width = 1.5 * res
    bins = np.floor((across - across.min(axis=1, keepdims=True)) / width).astype(np.intp)
    n_bins = int(bins.max()) + 1
    votes = np.bincount((bins + np.arange(len(angles))[:, None] * n_bins).ravel(),
                        minlength=len(angles) * n_bins).reshape(len(angles), n_bins)
    best = np.unravel_index(int(np.argmax(votes)), votes.shape)
    if votes[best] * res < WALL_MIN_M:
        return None
    a = float(angles[best[0]])
    return math.cos(a), math.sin(a)


def fit_line(samples: deque) -> Optional[tuple[float, float, float, float]]:
    """The least-squares line through centres ``(t s, x m, y m)``: where it puts them at the newest time (x, y m) and
    the velocity along it (vx, vy m/s); None with fewer than 3 or over less than 1 s."""
    if len(samples) < 3:
        return None
    arr = np.array(samples, dtype=float)
    if arr[-1, 0] - arr[0, 0] < 1.0:
        return None
    return _least_squares(arr)


def _least_squares(arr: np.ndarray) -> Optional[tuple[float, float, float, float]]:
    """The least-squares line through the rows ``(t s, x m, y m)`` of ``arr``: where it puts them at the last row's
    time (x, y m) and the velocity along it (vx, vy m/s); None when the times do not spread."""
    t_mean = float(arr[:, 0].mean())
    dt = arr[:, 0] - t_mean
    var = float((dt * dt).sum())
    if var <= 1e-9:
        return None
    vx = float((dt * (arr[:, 1] - arr[:, 1].mean())).sum() / var)
    vy = float((dt * (arr[:, 2] - arr[:, 2].mean())).sum() / var)
    t_end = float(arr[-1, 0])
    return (float(arr[:, 1].mean()) + vx * (t_end - t_mean), float(arr[:, 2].mean()) + vy * (t_end - t_mean), vx, vy)


def lane_direction(tr: Track, coming: int = 1) -> tuple[float, float]:
    """The direction (unit, odom) the lanes of a pass run in: against the person's walk when they come at the robot
    (``coming`` +1), along it when they catch it up from behind (-1); either way the robot's way. (Averaging it
    with the direction to the robot's target was tried: that carries the position estimate's error, and on a short
    way it put the person's line half a metre off at 9 m.)"""
    s = max(tr.speed_mps, 1e-6) * -coming
    return tr.vx / s, tr.vy / s


def side_name(side: int) -> str:
    """``left`` for +1, ``right`` for -1."""
    return "left" if side > 0 else "right"


def pursue(pose: tuple[float, float, float], carrot: tuple[float, float], speed_mps: float, max_turn_rps: float
           ) -> tuple[float, float]:
    """Pure pursuit toward ``carrot`` (odom, m) from ``pose`` (x m, y m, yaw rad): (v m/s, w rad/s); a turn in place
    while it is more than 60 deg off the heading."""
    dx, dy = carrot[0] - pose[0], carrot[1] - pose[1]
    ld = max(math.hypot(dx, dy), 1e-3)
    alpha = (math.atan2(dy, dx) - pose[2] + math.pi) % (2.0 * math.pi) - math.pi
    if abs(alpha) > math.radians(60.0):
        return 0.0, math.copysign(min(max_turn_rps, 1.5 * abs(alpha)), alpha)
    v = speed_mps
    w = v * 2.0 * math.sin(alpha) / ld
    if abs(w) > max_turn_rps:
        v *= max_turn_rps / abs(w)
        w = math.copysign(max_turn_rps, w)
    return v, w


__all__ = ["PersonTracker", "Track", "PassingPlanner", "Pass", "blobs", "fit_line", "pursue", "side_name",
           "wall_direction"]
