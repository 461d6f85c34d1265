"""Localisation on a saved map: a particle filter like ROS's AMCL, on 2D LiDAR scans and the odometry pose.

As in ROS, the odometry pose (``pose_odom``) stays continuous and never jumps;
this filter estimates where the robot is on the map and, from that, the
``map -> odom`` correction, so that ``map_pose = (map -> odom) o pose_odom``
can be carried forward with odometry between scans.

The method is AMCL's (Thrun, Burgard, Fox, *Probabilistic Robotics*, ch. 4, 6, 8):

* **motion model**: each particle moves by the odometry's motion since the
  last filter update, in the robot's frame, with noise growing with the
  rotation and the translation (``alpha1..4``, AMCL's ``odom_alpha*``);
* **measurement model**: the *likelihood field*. The distance from every cell
  to the nearest occupied cell is computed once (``cv2.distanceTransform``);
  each of about 60 beams of a scan is scored ``z_hit * exp(-d^2 / 2 sigma^2) +
  z_rand`` where its end point falls, looked up in a table; a particle's
  weight is the product over beams, tempered by ``beam_weight`` because
  neighbouring beams are not independent (AMCL sums the cubes for the same
  reason);
* **resampling**: low-variance (systematic) resampling after each update
  that moved the robot, as AMCL's ``resample_interval: 1``;
* **a wide start**: the first scan weighs ``candidates_per_injected`` times
  ``particles`` drawn from the initial uncertainty, then resamples to
  ``particles``, so that a start known to a metre and 30 degrees is covered
  densely enough (a fixed-size filter otherwise, not KLD);
* **recovery**: AMCL's ``recovery_alpha_slow``/``fast`` averages of the
  particles' mean beam likelihood; when the fast one drops below the slow one,
  random particles are injected over the free cells (a kidnapped robot is
  found again); and while the robot is not localised (a start far from where
  it is: the averages then have nothing better to compare with), a share
  ``lost_inject_share`` of them at every update. Each injected particle is
  the best of ``candidates_per_injected`` random poses scored against the
  current scan (sensor resetting, Lenser and Veloso 2000): plain random
  particles rarely land near the robot in a building of many rooms;
* **another place that fits as well** (twin rooms, a start given wrongly):
  once the cloud has settled, the whole map is searched (a correlative
  search, :meth:`MapLocaliser.search_map`) for another place that explains
  the scan within ``ambiguity_margin`` of the estimate; it gets a fixed
  share of the particles and the filter's weighing decides, scan after scan;
  while it holds its own after a few updates, ``localized`` is false.

The filter updates only when the robot has moved ``update_min_d_m`` or turned
``update_min_angle_deg`` since the last update (AMCL's ``update_min_d``/``a``):
weighting the same view again while standing still would make the estimate
overconfident. The reported covariance is the particles' weighted covariance
(around the estimate), so it is as wide as the cloud, plus the map's own
quantisation (``resolution^2 / 12`` on x and y); while the robot is not
localised, that of a pose anywhere on the map (uniform over its extent and
every heading) is added, since the cloud may be tight around a wrong place.
``match_quality`` is the share of the scan's beams that end within
``match_tolerance_m`` of an occupied cell at the estimate; ``localized`` turns false when it has stayed below
``lost_quality`` for ``lost_after_s``, and true again once it reaches
``found_quality`` (higher: a place that half fits the scan is not found).

Everything is vectorised with NumPy over particles x beams; random numbers
come from one seeded generator, so a run is the same for the same seed. Units:
metres, radians, seconds. Frames: ``map`` (the saved map's), ``odom`` (the
odometry's), ``base_link`` (x forward, y left).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from beastbt.core.config import dataclass_from_dict
from beastbt.core.schema_defaults import schema_defaults
from beastbt.mapping.occupancy_map import OccupancyMap

Pose2D = tuple[float, float, float]
"""(x m, y m, yaw rad)."""


@dataclass(frozen=True)
@schema_defaults("parts/localisation.schema.json")
class LocaliserConfig:
    """The robot profile's ``localisation:`` section (AMCL's knobs, in SI units)."""

    particles: int
    """Number of particles."""
    beams: int
    """Beams of a scan used per update (evenly spread over the returns)."""
    max_range_m: float
    """Returns farther than this are left out (m)."""
    sigma_hit_m: float
    """Standard deviation of a beam's end point around the nearest wall (m)."""
    z_hit: float
    """Weight of the hit part of a beam's likelihood."""
    z_rand: float
    """Weight of the random part (what the map does not explain: people, furniture moved)."""
    beam_weight: float
    """Exponent of each beam's likelihood (< 1: neighbouring beams are not independent)."""
    alpha1: float
    """Rotation noise from rotation (rad per rad)."""
    alpha2: float
    """Rotation noise from translation (rad per m)."""
    alpha3: float
    """Translation noise from translation (m per m)."""
    alpha4: float
    """Translation noise from rotation (m per rad)."""
    update_min_d_m: float
    """Translation since the last update before the next (m)."""
    update_min_angle_deg: float
    """Rotation since the last update before the next (deg)."""
    recovery_alpha_slow: float
    """Smoothing of the slow average of the beam likelihood (0 disables recovery)."""
    recovery_alpha_fast: float
    """Smoothing of the fast average of the beam likelihood."""
    lost_inject_share: float
    """Share of the particles drawn at random over the free cells at each update while not localised."""
    candidates_per_injected: int
    """Random poses scored against the scan for each particle injected (the best are kept); also how many times
    ``particles`` the first scan weighs, drawn from the initial uncertainty."""
    match_tolerance_m: float
    """A beam within this of an occupied cell matches the map (m)."""
    lost_quality: float
    """Match quality below which the robot is losing its place (share of beams)."""
    lost_after_s: float
    """How long the quality must stay below ``lost_quality`` before ``localized`` turns false (s)."""
    found_quality: float
    """Match quality at which a robot that was not localised counts as localised again (share of beams)."""
    ambiguity_check_interval_s: float
    """How often the whole map is searched for another place that explains the scan as well (s), once the cloud has
    settled (at :data:`SETTLED_CHECKS` updates in a row first). 0 turns the check off."""
    ambiguity_margin: float
    """How much better (mean log-likelihood per beam, nats) the estimate must explain the scan than the best other
    place for that place to be left alone; closer than this (or worse), particles go there and the filter's weighing
    decides (``localized`` is false while both hold)."""
    ambiguity_separation_m: float
    """Another place counts as another only this far from the estimate (m) or 30 degrees off."""

    def __post_init__(self) -> None:
        if self.particles < 10 or self.particles > 100_000:
            raise ValueError(f"localisation: 'particles' must be 10..100000, got {self.particles}")
        if self.beams < 4 or self.beams > 2000:
            raise ValueError(f"localisation: 'beams' must be 4..2000, got {self.beams}")
        for name in ("max_range_m", "sigma_hit_m", "beam_weight", "match_tolerance_m"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"localisation: '{name}' must be > 0, got {getattr(self, name)}")
        for name in ("alpha1", "alpha2", "alpha3", "alpha4", "update_min_d_m", "update_min_angle_deg",
                     "recovery_alpha_slow", "recovery_alpha_fast", "lost_after_s", "z_hit", "z_rand"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"localisation: '{name}' must be >= 0, got {getattr(self, name)}")
        if not self.z_rand > 0.0:
            raise ValueError("localisation: 'z_rand' must be > 0 (a beam the map cannot explain must not veto a pose)")
        if not 1 <= self.candidates_per_injected <= 1000:
            raise ValueError(f"localisation: 'candidates_per_injected' must be 1..1000, got "
                             f"{self.candidates_per_injected}")
        if not 0.0 <= self.lost_inject_share <= 1.0:
            raise ValueError(f"localisation: 'lost_inject_share' must be 0..1, got {self.lost_inject_share}")
        for name in ("ambiguity_check_interval_s", "ambiguity_margin", "ambiguity_separation_m"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"localisation: '{name}' must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.lost_quality <= self.found_quality <= 1.0:
            raise ValueError(f"localisation: 'lost_quality' ({self.lost_quality}) and 'found_quality' "
                             f"({self.found_quality}) must be 0..1, lost_quality <= found_quality")

    @classmethod
    def from_dict(cls, d: Any) -> "LocaliserConfig":
        """Build from a profile's ``localisation:`` mapping; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "localisation")


def wrap(a: Any) -> Any:
    """Angles (rad) wrapped into [-pi, pi)."""
    return (np.asarray(a) + math.pi) % (2.0 * math.pi) - math.pi


def compose(a: Pose2D, b: Pose2D) -> Pose2D:
    """The pose ``a o b``: ``b`` expressed in ``a``'s frame, turned into ``a``'s parent frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], float(wrap(a[2] + b[2])))


def invert(a: Pose2D) -> Pose2D:
    """The inverse transform of ``a``."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-c * a[0] - s * a[1], s * a[0] - c * a[1], float(wrap(-a[2])))


def scan_mid_s(scan: Any) -> float:
    """The clock time (s) of the middle of a scan's revolution (a :class:`~beastbt.blackboard.types.LaserScan`).

    Its points were measured over the revolution that ended at its stamp, so a
    robot turning at 1 rad/s turns 3 degrees between its middle and its end (at
    10 Hz): a scan matched, or drawn, at the pose of its end would put the
    robot's heading that much behind in every turn.
    """
    span = scan.scan_time_s
    return scan.stamp_s - 0.5 * span if math.isfinite(span) and 0.0 < span < 1.0 else scan.stamp_s


COARSE_STEP_M = 0.25
"""The global search's grid step over the map (m)."""
COARSE_HEADINGS = 36
"""The global search's headings (every 10 degrees)."""
COARSE_SIGMA_M = 0.2
"""The width of the coarse likelihood the global search scores with (m): about its grid step."""
COARSE_BEAMS = 16
"""Beams of the scan the coarse search scores (the refinement uses all of ``beams``)."""
SETTLED_CHECKS = 3
"""Once the cloud has settled (after a start, or when the robot is localised again), the map is searched at this
many filter updates in a row; then every ``ambiguity_check_interval_s``."""
TIGHT_CLOUD_M = 0.5
"""The cloud's spread (m, over x and y together) below which it counts as settled, and is compared with the map."""
TIGHT_CLOUD_DEG = 15.0
"""The cloud's heading spread (degrees) below which it counts as settled."""
INJECT_BELOW_SHARE = 0.05
"""Particles go to another place that fits as well only when the cloud has less than this share of its weight there."""
FOLLOW_SHARE = 0.2
"""The share of the particles sent to another place that fits about as well as the estimate (or better): a fixed
minority, whatever one scan says, so that the filter's own weighing, scan after scan, decides between the two."""
AMBIGUOUS_SHARE = 0.1
"""The share of the cloud's weight the other place must hold, after :data:`EVIDENCE_UPDATES` updates, for the robot
not to count as localised: half what it was given, i.e. the scans since have not made it more than twice less likely
than the estimate."""
EVIDENCE_UPDATES = 5
"""Filter updates (scans) the other place is weighed for before it can make the robot not localised: one scan that
happens not to see what tells two places apart (a plant, a door) is no evidence that they are alike."""
TRUSTED_UPDATES = 25
"""Filter updates with a match of at least ``found_quality``, localised all along with no other place in question, after
which the estimate is trusted over what one scan says elsewhere: the map is no longer searched. The odometry has then
carried it, step by step, from where it was found, and a place elsewhere that fits better (a box, a person the map
does not show spoils the scan where the robot is) is more likely wrong than a jump across the map. Recovery (random
particles) still acts if the match is lost."""
SEARCH_CANDIDATES = 12
"""Best coarse poses refined (distinct places, at least a grid step apart)."""


class LikelihoodField:
    """Per-cell log-likelihood of a beam ending there, and the distance to the nearest occupied cell (m).

    Both tables are padded with one cell all round: an end point off the map
    is clipped onto that border, where it scores as a random return and is
    far from any wall.
    """

    def __init__(self, grid: OccupancyMap, config: LocaliserConfig) -> None:
        import cv2  # the distance transform: OpenCV's is exact (DIST_L2, DIST_MASK_PRECISE) and fast

        self.grid = grid
        occupied = grid.occupied()
        free_of_walls = np.where(occupied, 0, 255).astype(np.uint8)
        if occupied.any():
            dist_m = cv2.distanceTransform(free_of_walls, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * grid.resolution_m
        else:
            dist_m = np.full(occupied.shape, np.inf, dtype=np.float32)
        far = 1e6
        d = np.minimum(dist_m.astype(np.float64), far)
        logp = np.log(config.z_hit * np.exp(-0.5 * (d / config.sigma_hit_m) ** 2) + config.z_rand)
        self.log_p = np.pad(logp.astype(np.float32), 1, constant_values=math.log(config.z_rand))
        self.dist_m = np.pad(d.astype(np.float32), 1, constant_values=far)
        self.free_cells = np.flatnonzero(grid.free().ravel())
        # For the global search (MapLocaliser.search_map): a likelihood as wide as the search's grid step, so that
        # a pose on the coarse grid near the right one still scores as a match.
        # Padded by the LiDAR's range all round, so that no end point of a pose on the map falls off it: the
        # search then adds whole-cell offsets to flat indices, with no clipping.
        wide = COARSE_SIGMA_M
        self.coarse_pad = int(math.ceil(config.max_range_m / grid.resolution_m)) + 2
        self.log_p_coarse = np.pad(np.log(config.z_hit * np.exp(-0.5 * (d / wide) ** 2) + config.z_rand)
                                   .astype(np.float32), self.coarse_pad, constant_values=math.log(config.z_rand))
        self._c = math.cos(grid.origin_yaw)
        self._s = math.sin(grid.origin_yaw)

    def cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map-frame points (m) to (row, col) indices into the padded tables, clipped onto the border."""
        g = self.grid
        dx, dy = x - g.origin_x, y - g.origin_y
        if g.origin_yaw:
            dx, dy = self._c * dx + self._s * dy, -self._s * dx + self._c * dy
        inv = 1.0 / g.resolution_m
        col = np.clip(np.floor(dx * inv).astype(np.int64) + 1, 0, g.cols + 1)
        row = np.clip(np.floor(dy * inv).astype(np.int64) + 1, 0, g.rows + 1)
        return row, col


class MapLocaliser:
    """AMCL-like particle filter on an :class:`OccupancyMap` (see the module docstring).

    Call :meth:`start` with the initial pose and its uncertainty, then
    :meth:`update` with each new scan's points (base_link, m) and the odometry
    pose at that time. :attr:`map_from_odom` is the current ``map -> odom``
    transform; :meth:`map_pose_of` turns an odometry pose into the map.
    """

    def __init__(self, grid: OccupancyMap, config: LocaliserConfig, rng: np.random.Generator) -> None:
        self.grid = grid
        self.config = config
        self.rng = rng
        self.field = LikelihoodField(grid, config)
        n = config.particles
        self.px = np.zeros(n)
        self.py = np.zeros(n)
        self.pth = np.zeros(n)
        self.w = np.full(n, 1.0 / n)
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.map_from_odom: Pose2D = (0.0, 0.0, 0.0)
        self.last_odom: Optional[Pose2D] = None
        """The odometry pose at the last filter update (None before the first scan)."""
        self.covariance = np.zeros((3, 3))
        self.match_quality = 1.0
        self.localized = True
        self._low_since: Optional[float] = None
        self.updates = 0
        """Filter updates done (a scan after enough motion)."""
        self.injected = 0
        """Particles injected by recovery, or sent to another place that fits as well, so far."""
        self.ambiguous = False
        """Another place on the map explains the scans about as well as the estimate: ``localized`` is false until
        one of them wins (the particles follow both meanwhile)."""
        self.alternative: Optional[Pose2D] = None
        """The other place the particles follow (map frame), or None."""
        self.searches = 0
        """Global searches of the map done."""
        self._alternative_from_odom: Optional[Pose2D] = None
        """The other place followed, as a map -> odom transform (so that it moves with the robot), or None."""
        self._weighed = 0
        """Filter updates since particles were last sent to the other place (the evidence gathered on it)."""
        self._next_search_s: Optional[float] = None
        self._moved_while_ambiguous = False
        """The estimate moved to the other place while the question was open."""
        self._localized_before_ambiguity: Optional[bool] = None
        """``localized`` when another place was found to fit as well (restored once one of them wins), or None."""
        self._track_updates = 0
        """Filter updates in a row localised with a good match, no other place in question (see TRUSTED_UPDATES)."""
        self._open_checks = 0
        """Searches in a row that must find no other place before an open question (``ambiguous``) is closed."""
        self._settle_checks = SETTLED_CHECKS
        """Searches left to do at every update (the cloud has just settled); then one every interval."""
        self._cluster_xy_var = math.inf
        self._cluster_yaw_var = math.inf
        """The spread of the particles around the estimate (m^2 over x and y together; rad^2): the cloud there."""
        self._search_coarse = self._coarse_poses()

    # -- set-up -------------------------------------------------------------------------------------------------
    def start(self, pose: Pose2D, sigma_xy_m: float, sigma_yaw_rad: float, odom: Pose2D) -> None:
        """Spread the particles around ``pose`` (map) with these standard deviations; ``odom`` is the odometry
        pose at that moment (the ``map -> odom`` transform follows from the two). Called again mid-run (ROS's
        ``/initialpose``), the new pose is judged afresh, as the first: localised until the scans say otherwise,
        and searched against the map once the cloud settles there."""
        # The first scan weighs candidates_per_injected times as many particles as the filter keeps (only
        # once, so it costs little): a wide initial uncertainty is then covered densely enough for some to lie
        # near the robot; resampling brings the cloud back to its size.
        n = self.config.particles * self.config.candidates_per_injected
        self.px = pose[0] + self.rng.normal(0.0, sigma_xy_m, n)
        self.py = pose[1] + self.rng.normal(0.0, sigma_xy_m, n)
        self.pth = wrap(pose[2] + self.rng.normal(0.0, sigma_yaw_rad, n))
        self.w = np.full(n, 1.0 / n)
        self.covariance = np.diag([sigma_xy_m ** 2, sigma_xy_m ** 2, sigma_yaw_rad ** 2])
        self.map_from_odom = compose(pose, invert(odom))
        self.last_odom = None
        self._start_odom = odom
        # A start again (ROS's /initialpose) is a claim like the first, judged afresh: what the filter had come to
        # trust where it was before says nothing of the new place. Without this, an estimate trusted for
        # TRUSTED_UPDATES would never have the new place searched against the map, and a pose given wrongly in a
        # place that fits (the lab for the office) would be driven on, localised, for as long as it fits.
        self.localized = True
        self._low_since = None
        self.w_slow = self.w_fast = 0.0
        self.ambiguous = False
        self.alternative = None
        self._alternative_from_odom = None
        self._localized_before_ambiguity = None
        self._moved_while_ambiguous = False
        self._weighed = 0
        self._track_updates = 0
        self._open_checks = 0
        self._settle_checks = SETTLED_CHECKS
        self._next_search_s = None
        self._cluster_xy_var = self._cluster_yaw_var = math.inf

    @property
    def pose_covariance(self) -> np.ndarray:
        """The covariance to report (3x3 over x, y, yaw; m^2, rad^2): the cloud's, and while the robot is not
        localised that of a pose anywhere on the map (uniform over its extent, any heading) on top, since the
        cloud may then be tight around a wrong place."""
        if self.localized:
            return self.covariance
        g = self.grid
        return self.covariance + np.diag([g.width_m ** 2 / 12.0, g.height_m ** 2 / 12.0, math.pi ** 2 / 3.0])

    def map_pose_of(self, odom: Pose2D) -> Pose2D:
        """The odometry pose ``odom`` carried into the map by the current ``map -> odom`` transform."""
        return compose(self.map_from_odom, odom)

    # -- one scan -----------------------------------------------------------------------------------------------
    def select_beams(self, points: np.ndarray) -> np.ndarray:
        """About ``config.beams`` of the scan's points (base_link, m), evenly spread, within ``max_range_m``."""
        if len(points) == 0:
            return points
        r2 = points[:, 0] ** 2 + points[:, 1] ** 2
        pts = points[r2 <= self.config.max_range_m ** 2]
        if len(pts) > self.config.beams:
            idx = np.linspace(0, len(pts) - 1, self.config.beams).astype(np.int64)
            pts = pts[idx]
        return pts

    def update(self, now_s: float, points: np.ndarray, odom: Pose2D) -> bool:
        """Take one scan: ``points`` its returns (n, 2) in base_link (m), ``odom`` the odometry pose when it was
        measured. Moves and weighs the particles when the robot has moved enough; always refreshes the match
        quality and ``localized``. Returns True when the filter updated."""
        beams = self.select_beams(points)
        if len(beams) < 4:
            self._judge(now_s, 0.0)
            return False
        cfg = self.config
        first = self.last_odom is None
        if first:
            self._predict(self._start_odom, odom)
        else:
            assert self.last_odom is not None
            step = compose(invert(self.last_odom), odom)
            moved = math.hypot(step[0], step[1]) >= cfg.update_min_d_m
            turned = abs(step[2]) >= math.radians(cfg.update_min_angle_deg)
            if not (moved or turned):
                self._judge(now_s, self._quality(beams, self.map_pose_of(odom)))
                return False
            self._predict(self.last_odom, odom)
        self.last_odom = odom
        mean_log_p = self._weigh(beams)
        est = self._estimate()
        before = self.map_pose_of(odom)
        self.map_from_odom = compose(est, invert(odom))
        if not first:  # the first update weighs the whole initial spread: its average says nothing of a match
            self._recover_average(mean_log_p)
        self._resample(beams)
        self.updates += 1
        quality = self._quality(beams, est)
        if cfg.ambiguity_check_interval_s > 0.0:
            self._follow_both(now_s, beams, est, before, odom, quality)
        self._judge(now_s, quality)
        return True

    def no_scan(self, now_s: float) -> None:
        """The LiDAR has gone quiet: nothing matches the map now (``localized`` turns false after
        ``lost_after_s``, as for a poor match); the pose is carried by odometry alone meanwhile."""
        self._judge(now_s, 0.0)

    def _predict(self, before: Pose2D, after: Pose2D) -> None:
        """Move every particle by the odometry's motion from ``before`` to ``after``, with AMCL's noise."""
        dx, dy, dth = compose(invert(before), after)
        trans = math.hypot(dx, dy)
        a = self.config
        n = len(self.px)
        sd_rot = a.alpha1 * abs(dth) + a.alpha2 * trans
        sd_trans = a.alpha3 * trans + a.alpha4 * abs(dth)
        rng = self.rng
        ndx = dx + rng.normal(0.0, sd_trans + 1e-9, n)
        ndy = dy + rng.normal(0.0, sd_trans + 1e-9, n)
        ndth = dth + rng.normal(0.0, sd_rot + 1e-9, n)
        c, s = np.cos(self.pth), np.sin(self.pth)
        self.px = self.px + c * ndx - s * ndy
        self.py = self.py + s * ndx + c * ndy
        self.pth = wrap(self.pth + ndth)

    def _weigh(self, beams: np.ndarray) -> np.ndarray:
        """Multiply each particle's weight by its scan likelihood; the mean log-likelihood per beam of each."""
        c, s = np.cos(self.pth)[:, None], np.sin(self.pth)[:, None]
        bx, by = beams[:, 0][None, :], beams[:, 1][None, :]
        ex = self.px[:, None] + c * bx - s * by
        ey = self.py[:, None] + s * bx + c * by
        row, col = self.field.cells(ex, ey)
        log_p = self.field.log_p[row, col]
        total = log_p.sum(axis=1, dtype=np.float64)
        log_w = np.log(np.maximum(self.w, 1e-300)) + self.config.beam_weight * total
        log_w -= log_w.max()
        w = np.exp(log_w)
        self.w = w / w.sum()
        return total / beams.shape[0]

    def _estimate(self) -> Pose2D:
        """The weighted mean of the heaviest cluster of particles; the weighted covariance of all around it."""
        w, px, py, pth = self.w, self.px, self.py, self.pth
        # The heaviest 1.5 m square (3 x 3 bins of 0.5 m): after recovery a few far particles must not drag the mean
        # between two places, and a small dense clump (particles just sent to another place) must not outweigh a
        # cloud spread over a few bins.
        key_x = np.floor(px / 0.5).astype(np.int64)
        key_y = np.floor(py / 0.5).astype(np.int64)
        key_x -= key_x.min() - 1
        key_y -= key_y.min() - 1
        shape = (int(key_x.max()) + 2, int(key_y.max()) + 2)
        bins = np.bincount(key_x * shape[1] + key_y, weights=w, minlength=shape[0] * shape[1]).reshape(shape)
        window = sum(np.roll(np.roll(bins, i, axis=0), j, axis=1) for i in (-1, 0, 1) for j in (-1, 0, 1))
        hx, hy = np.unravel_index(int(np.argmax(window)), shape)
        centre = (np.abs(key_x - hx) <= 1) & (np.abs(key_y - hy) <= 1)
        cx = float(np.average(px[centre], weights=w[centre] + 1e-300))
        cy = float(np.average(py[centre], weights=w[centre] + 1e-300))
        near = (px - cx) ** 2 + (py - cy) ** 2 <= 1.0
        wn = w[near] + 1e-300
        x = float(np.average(px[near], weights=wn))
        y = float(np.average(py[near], weights=wn))
        yaw = float(math.atan2(np.average(np.sin(pth[near]), weights=wn), np.average(np.cos(pth[near]), weights=wn)))
        self._cluster_xy_var = float(np.average((px[near] - x) ** 2 + (py[near] - y) ** 2, weights=wn))
        self._cluster_yaw_var = float(np.average(wrap(pth[near] - yaw) ** 2, weights=wn))
        d = np.stack((px - x, py - y, wrap(pth - yaw)))
        cov = (d * w) @ d.T
        # The map itself is only known to a cell: add the variance of that quantisation (res^2 / 12) on x and y,
        # which the particles cannot see (they all weigh the same cells).
        quantisation = self.grid.resolution_m ** 2 / 12.0
        self.covariance = 0.5 * (cov + cov.T) + np.diag([quantisation, quantisation, 0.0])
        return (x, y, yaw)

    def _recover_average(self, mean_log_p: np.ndarray) -> None:
        """AMCL's slow and fast averages of the particles' beam likelihood (geometric mean per beam)."""
        cfg = self.config
        w_avg = float(np.mean(np.exp(mean_log_p)))
        if self.w_slow == 0.0:
            self.w_slow, self.w_fast = w_avg, w_avg
        else:
            self.w_slow += cfg.recovery_alpha_slow * (w_avg - self.w_slow)
            self.w_fast += cfg.recovery_alpha_fast * (w_avg - self.w_fast)

    def _random_poses(self, count: int, beams: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``count`` poses over the free cells that explain this scan best among ``candidates_per_injected`` times
        as many drawn uniformly (free cells, any heading): sensor resetting (Lenser and Veloso, 2000), so that a
        handful of random particles has a chance to land where the robot is."""
        g, rng = self.grid, self.rng
        m = min(count * self.config.candidates_per_injected, 20_000)
        cells = rng.choice(self.field.free_cells, m)
        row, col = np.divmod(cells, g.cols)
        x, y = g.cell_centres(col + rng.random(m) - 0.5, row + rng.random(m) - 0.5)
        th = rng.uniform(-math.pi, math.pi, m)
        c, s = np.cos(th)[:, None], np.sin(th)[:, None]
        ex = x[:, None] + c * beams[:, 0][None, :] - s * beams[:, 1][None, :]
        ey = y[:, None] + s * beams[:, 0][None, :] + c * beams[:, 1][None, :]
        row_e, col_e = self.field.cells(ex, ey)
        score = self.field.log_p[row_e, col_e].sum(axis=1)
        best = np.argpartition(-score, count - 1)[:count] if count < m else np.arange(m)
        return np.asarray(x)[best], np.asarray(y)[best], th[best]

    def _resample(self, beams: np.ndarray) -> None:
        """Low-variance resampling; a share ``1 - w_fast / w_slow`` of the new particles is drawn at random over
        the free cells (AMCL's recovery)."""
        cfg = self.config
        n = cfg.particles  # the first update weighs more (see start); the cloud keeps this many
        inject = 0
        if len(self.field.free_cells):
            share = 0.0
            if cfg.recovery_alpha_slow > 0.0 and self.w_slow > 0.0:
                share = max(0.0, 1.0 - self.w_fast / self.w_slow)
            if not self.localized:
                # Started lost (or lost for long): the averages have nothing better to compare with, so search.
                share = max(share, cfg.lost_inject_share)
            inject = int(self.rng.binomial(n, min(share, 1.0))) if share > 0.0 else 0
        keep = n - inject
        positions = (self.rng.random() + np.arange(keep)) / max(keep, 1)
        idx = np.minimum(np.searchsorted(np.cumsum(self.w), positions), len(self.w) - 1)
        px, py, pth = self.px[idx], self.py[idx], self.pth[idx]
        if inject:
            cx, cy, cth = self._random_poses(inject, beams)
            px = np.concatenate((px, cx))
            py = np.concatenate((py, cy))
            pth = np.concatenate((pth, cth))
            self.injected += inject
            # The averages restart from the level reached: otherwise every update would inject again.
            self.w_fast = self.w_slow
        self.px, self.py, self.pth = px, py, pth
        self.w = np.full(n, 1.0 / n)

    # -- another place that fits as well ----------------------------------------------------------------------
    def _coarse_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """The global search's positions: free cells of the map on a :data:`COARSE_STEP_M` grid (x, y in m)."""
        g = self.grid
        step = max(1, int(round(COARSE_STEP_M / g.resolution_m)))
        free = g.free()
        rows, cols = np.nonzero(free[::step, ::step])
        x, y = g.cell_centres(cols * step, rows * step)
        return np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)

    def _scores(self, x: np.ndarray, y: np.ndarray, th: np.ndarray, beams: np.ndarray,
                table: np.ndarray) -> np.ndarray:
        """Mean log-likelihood per beam of ``beams`` (base_link) at each pose, looked up in ``table``."""
        c, s = np.cos(th)[:, None], np.sin(th)[:, None]
        ex = x[:, None] + c * beams[:, 0][None, :] - s * beams[:, 1][None, :]
        ey = y[:, None] + s * beams[:, 0][None, :] + c * beams[:, 1][None, :]
        row, col = self.field.cells(ex, ey)
        return table[row, col].mean(axis=1)

    def _refine(self, pose: Pose2D, beams: np.ndarray) -> tuple[Pose2D, float]:
        """A local search around ``pose`` on the fine likelihood (shrinking steps); the best pose and its score."""
        rng = self.rng
        best = np.array(pose, dtype=np.float64)
        best_score = float(self._scores(best[:1], best[1:2], best[2:3], beams, self.field.log_p)[0])
        for sd_xy, sd_th in ((0.15, 0.12), (0.06, 0.05), (0.02, 0.02), (0.008, 0.008), (0.003, 0.003)):
            x = best[0] + rng.normal(0.0, sd_xy, 24)
            y = best[1] + rng.normal(0.0, sd_xy, 24)
            th = best[2] + rng.normal(0.0, sd_th, 24)
            scores = self._scores(x, y, th, beams, self.field.log_p)
            i = int(np.argmax(scores))
            if scores[i] > best_score:
                best, best_score = np.array([x[i], y[i], th[i]]), float(scores[i])
        # Then a polish on a small grid round the best, so that two places refined alike are compared alike (the
        # random draws alone leave a centimetre or two to chance).
        d = np.array([(dx, dy, dth) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dth in (-1, 0, 1)], dtype=np.float64)
        for step, turn in ((0.02, 0.01), (0.01, 0.005), (0.005, 0.0025)):
            x, y, th = best[0] + step * d[:, 0], best[1] + step * d[:, 1], best[2] + turn * d[:, 2]
            scores = self._scores(x, y, th, beams, self.field.log_p)
            i = int(np.argmax(scores))
            if scores[i] > best_score:
                best, best_score = np.array([x[i], y[i], th[i]]), float(scores[i])
        return (float(best[0]), float(best[1]), float(wrap(best[2]))), best_score

    def search_map(self, beams: np.ndarray) -> list[tuple[Pose2D, float]]:
        """The places on the whole map that best explain ``beams`` (base_link, m), best first, each refined on the
        fine likelihood: (pose, mean log-likelihood per beam). A correlative search: every free cell of a
        :data:`COARSE_STEP_M` grid at :data:`COARSE_HEADINGS` headings, scored on a few beams against a widened
        likelihood, then the best distinct ones refined."""
        cx, cy = self._search_coarse
        if len(cx) == 0 or len(beams) < 4:
            return []
        idx = np.linspace(0, len(beams) - 1, min(COARSE_BEAMS, len(beams))).astype(np.int64)
        few = beams[idx]
        headings = np.arange(COARSE_HEADINGS) * (2.0 * math.pi / COARSE_HEADINGS)
        best_score = np.full(len(cx), -np.inf, dtype=np.float32)
        best_th = np.zeros(len(cx))
        # In whole cells of the padded table: each position's cell once, each heading's beam offsets once, and a
        # flat look-up of their sums (an end point off the table is clipped onto its border row or column).
        g = self.grid
        table = self.field.log_p_coarse
        cols_p = table.shape[1]
        pad = self.field.coarse_pad
        r0, c0 = self.field.cells(cx, cy)  # in the 1-cell padded tables: positions are on the map
        base = (r0 - 1 + pad) * cols_p + (c0 - 1 + pad)
        inv = 1.0 / g.resolution_m
        cg, sg = math.cos(g.origin_yaw), math.sin(g.origin_yaw)
        flat = table.ravel()
        for th in headings:
            c, s = math.cos(th), math.sin(th)
            ox = c * few[:, 0] - s * few[:, 1]
            oy = s * few[:, 0] + c * few[:, 1]
            dc = np.rint((cg * ox + sg * oy) * inv).astype(np.int64)
            dr = np.rint((-sg * ox + cg * oy) * inv).astype(np.int64)
            score = flat[base[:, None] + (dr * cols_p + dc)[None, :]].sum(axis=1)
            better = score > best_score
            best_score[better] = score[better]
            best_th[better] = th
        best_score /= len(few)
        order = np.argsort(-best_score)
        picked: list[int] = []
        for i in order:
            if all((cx[i] - cx[j]) ** 2 + (cy[i] - cy[j]) ** 2 > (2 * COARSE_STEP_M) ** 2 for j in picked):
                picked.append(int(i))
                if len(picked) >= SEARCH_CANDIDATES:
                    break
        found = [self._refine((float(cx[i]), float(cy[i]), float(best_th[i])), beams) for i in picked]
        self.searches += 1
        return sorted(found, key=lambda f: -f[1])

    def _apart(self, a: Pose2D, b: Pose2D) -> bool:
        """``a`` and ``b`` are different places: ``ambiguity_separation_m`` apart, or 30 degrees."""
        return (math.hypot(a[0] - b[0], a[1] - b[1]) > self.config.ambiguity_separation_m
                or abs(float(wrap(a[2] - b[2]))) > math.radians(30.0))

    def _other_place(self, beams: np.ndarray, est: Pose2D) -> Optional[tuple[Pose2D, Pose2D]]:
        """Search the whole map (:meth:`search_map`) for another place that explains ``beams`` within
        ``ambiguity_margin`` of the estimate, or better; None when the estimate explains them clearly best. The
        estimate is refined the same way as the places found, so that a cloud's mean a few centimetres off does
        not lose to a place polished by the search. The other place and the estimate refined, or None."""
        refined, est_score = self._refine(est, beams)
        for pose, score in self.search_map(beams):
            if self._apart(pose, est):
                return (pose, refined) if score >= est_score - self.config.ambiguity_margin else None
        return None

    def _align(self, x: np.ndarray, y: np.ndarray, th: np.ndarray, pose: Pose2D,
               beams: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The particles (x, y, th) moved as one, by the small shift and turn about ``pose`` under which they explain
        ``beams`` best (the sum of their likelihoods): two refined poses correspond only to a centimetre or two
        (worse on a scan taken while turning), and that much costs a settled cloud most of its weight."""
        bw = self.config.beam_weight
        for step, turn in ((0.02, 0.01), (0.01, 0.005), (0.005, 0.0025)):
            best, best_score = (0.0, 0.0, 0.0), -np.inf
            for dth in (-turn, 0.0, turn):
                c, s = math.cos(dth), math.sin(dth)
                rx = pose[0] + c * (x - pose[0]) - s * (y - pose[1])
                ry = pose[1] + s * (x - pose[0]) + c * (y - pose[1])
                for dx in (-step, 0.0, step):
                    for dy in (-step, 0.0, step):
                        total = self._scores(rx + dx, ry + dy, th + dth, beams, self.field.log_p) * len(beams)
                        score = float(np.logaddexp.reduce(bw * total))
                        if score > best_score:
                            best, best_score = (dx, dy, dth), score
            dx, dy, dth = best
            c, s = math.cos(dth), math.sin(dth)
            x, y = (pose[0] + c * (x - pose[0]) - s * (y - pose[1]) + dx,
                    pose[1] + s * (x - pose[0]) + c * (y - pose[1]) + dy)
            th = th + dth
            pose = (pose[0] + dx, pose[1] + dy, pose[2] + dth)
        return x, y, wrap(th)

    def _send_particles(self, pose: Pose2D, est: Pose2D, odom: Pose2D, beams: np.ndarray) -> None:
        """Move :data:`FOLLOW_SHARE` of the particles (drawn at random) to ``pose`` and follow it from now on. Each
        keeps its offset from the estimate (the whole cloud's shape is carried over, rotated): particles scattered
        more loosely than the settled cloud would lose to it on their scatter alone, not on the place."""
        n = len(self.px)
        k = int(n * FOLLOW_SHARE)
        pick = self.rng.choice(n, k, replace=False)
        # The estimate's place onto the other one: ``est`` refined as ``pose`` was, so that the two correspond as
        # closely as they can (a centimetre off costs the particles sent there much of their weight).
        t = compose(pose, invert(est))
        c, s = math.cos(t[2]), math.sin(t[2])
        x, y = self.px[pick], self.py[pick]
        x, y, th = t[0] + c * x - s * y, t[1] + s * x + c * y, self.pth[pick] + t[2]
        self.px[pick], self.py[pick], self.pth[pick] = self._align(x, y, th, pose, beams)
        self.w = np.full(n, 1.0 / n)  # just resampled: every particle weighs the same
        self.injected += k

    def _follow_both(self, now_s: float, beams: np.ndarray, est: Pose2D, before: Pose2D,
                     odom: Pose2D, quality: float) -> None:
        """Another place that fits as well (twin rooms, a start given wrongly). Once the cloud has settled, the
        whole map is searched (at :data:`SETTLED_CHECKS` updates in a row, then every
        ``ambiguity_check_interval_s``); a place that explains the scan about as well as the estimate (or better)
        is given :data:`FOLLOW_SHARE` of the particles, and the filter's weighing, scan after scan, decides: after
        :data:`EVIDENCE_UPDATES` updates, while the other place still holds :data:`AMBIGUOUS_SHARE` of the weight,
        ``ambiguous`` is true (``localized`` false); when it holds the most, it becomes the estimate and the place
        the estimate was at becomes the other one. ``before`` is the estimate before this update, ``quality`` the
        scan's match quality at the estimate: a scan the estimate explains poorly (below ``lost_quality``: people,
        a box the map does not show, or a robot lost) is not compared with the map, since a place that lacks what
        spoils it would win on it (recovery searches for a lost robot). Nor once the estimate is trusted
        (:data:`TRUSTED_UPDATES`)."""
        cfg = self.config
        if self._alternative_from_odom is not None:
            alt = compose(self._alternative_from_odom, odom)
            if not self._apart(alt, est):
                # The estimate moved to the other place: the place it left is now the other one, weighed as a new one.
                if self._apart(before, est):
                    self._alternative_from_odom = compose(before, invert(odom))
                    self._weighed = 0
                    self.ambiguous = True
                    self._moved_while_ambiguous = True
                else:
                    self._alternative_from_odom = None
            if self._alternative_from_odom is not None:
                alt = compose(self._alternative_from_odom, odom)
                self._weighed += 1
                if self._weighed >= EVIDENCE_UPDATES:
                    if self._share_near(alt) >= AMBIGUOUS_SHARE:
                        self.ambiguous = True
                    else:
                        # The scans made the other place unlikely. If it was an open question, it stays open until
                        # searches at SETTLED_CHECKS updates in a row find no other place: the cloud's own drift may
                        # have thinned a place that fits just as well, and one search may miss it.
                        self._alternative_from_odom = None
                        self._open_checks = SETTLED_CHECKS if self.ambiguous else 0
        self.alternative = (None if self._alternative_from_odom is None
                            else compose(self._alternative_from_odom, odom))
        tight = (self._cluster_xy_var <= TIGHT_CLOUD_M ** 2
                 and self._cluster_yaw_var <= math.radians(TIGHT_CLOUD_DEG) ** 2)
        if not tight or (not self.localized and not self.ambiguous):
            # Only a cloud that has settled somewhere is compared with the rest of the map: a wide one (a start
            # known to a metre) is still finding its place, and its mean would lose to any place that fits.
            self._settle_checks = SETTLED_CHECKS
            self._next_search_s = None
            return
        if not self.localized or self.ambiguous:
            self._track_updates = 0
        elif quality >= cfg.found_quality:
            self._track_updates += 1  # (a scan spoiled by something the map lacks neither counts nor resets it)
        if self._alternative_from_odom is not None:
            return  # the particles follow both places: the scans decide, no search needed meanwhile
        if quality < cfg.lost_quality or (self._track_updates >= TRUSTED_UPDATES and self._open_checks == 0):
            return
        if not (self._open_checks > 0 or self._settle_checks > 0 or self._next_search_s is None
                or now_s >= self._next_search_s):
            return
        self._settle_checks = max(0, self._settle_checks - 1)
        self._next_search_s = now_s + cfg.ambiguity_check_interval_s
        found = self._other_place(beams, est)
        if found is None:
            if self._open_checks > 0:
                self._open_checks -= 1
                self.ambiguous = self._open_checks > 0
            return
        other, refined = found
        if self._share_near(other) < INJECT_BELOW_SHARE:
            self._send_particles(other, refined, odom, beams)
        self._alternative_from_odom = compose(other, invert(odom))
        self.alternative = other
        self._weighed = 0
        self._open_checks = 0  # ``ambiguous`` as it was, while the particles there are weighed

    def _share_near(self, pose: Pose2D) -> float:
        """The share of the particles' weight within 0.5 m and 30 degrees of ``pose``."""
        near = (((self.px - pose[0]) ** 2 + (self.py - pose[1]) ** 2 <= 0.25)
                & (np.abs(wrap(self.pth - pose[2])) <= math.radians(30.0)))
        return float(self.w[near].sum())

    def _quality(self, beams: np.ndarray, pose: Pose2D) -> float:
        """Share of ``beams`` (base_link) that end within ``match_tolerance_m`` of an occupied cell at ``pose``."""
        c, s = math.cos(pose[2]), math.sin(pose[2])
        ex = pose[0] + c * beams[:, 0] - s * beams[:, 1]
        ey = pose[1] + s * beams[:, 0] + c * beams[:, 1]
        row, col = self.field.cells(ex, ey)
        return float(np.mean(self.field.dist_m[row, col] <= self.config.match_tolerance_m))

    def _judge(self, now_s: float, quality: float) -> None:
        """Keep the match quality; ``localized`` turns false once it has stayed below ``lost_quality`` for
        ``lost_after_s``, and true again only at ``found_quality`` (a hysteresis: a place on the map that only
        half fits the scan does not count as found)."""
        self.match_quality = quality
        cfg = self.config
        if self.ambiguous:
            if self._localized_before_ambiguity is None:
                self._localized_before_ambiguity = self.localized
                self._moved_while_ambiguous = False
            self.localized = False  # two places fit: saying either would be a guess
            self._low_since = None
            return
        if self._localized_before_ambiguity is not None:
            # One place won. If it is the place the robot was localised at when the question arose, it is as
            # localised as it was, judged by the match as any localised robot is (a match spoiled by something the
            # map does not show, between lost_quality and found_quality, does not keep it unlocalised); a place
            # it moved to must reach found_quality first.
            self.localized = self._localized_before_ambiguity and not self._moved_while_ambiguous
            self._localized_before_ambiguity = None
        if not self.localized:
            if quality >= cfg.found_quality:
                self.localized = True
                self._low_since = None
            return
        if quality >= cfg.lost_quality:
            self._low_since = None
            return
        if self._low_since is None:
            self._low_since = now_s
        if now_s - self._low_since >= cfg.lost_after_s:
            self.localized = False


__all__ = ["MapLocaliser", "LocaliserConfig", "LikelihoodField", "compose", "invert", "wrap", "scan_mid_s",
           "Pose2D"]
