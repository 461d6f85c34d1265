"""Correlative scan matching (Olson 2009, "Real-time correlative scan matching"), as Karto and slam_toolbox do.

A scan (points in base_link, metres) is matched against reference points
(the map built so far, or older keyframes' scans, in the map frame):

1. The reference points are drawn into a grid at ``resolution_m`` and blurred
   into a *likelihood field*: ``exp(-d^2 / (2 sigma^2))`` with ``d`` the
   distance to the nearest reference point (OpenCV's exact distance
   transform), so a scan point scores 1 on a wall and ~0 half a metre off it.
2. Coarse to fine: the field is max-filtered over ``coarse_factor`` cells
   (each coarse cell an upper bound of the fine cells it covers); every
   heading in the window is tried and every coarse translation scored for all
   points at once (NumPy gathers); the coarse candidates are then refined at
   the fine resolution best first, and a coarse candidate is dropped as soon
   as its upper bound falls below the best fine score: Olson's multi-resolution
   search, exact at the fine resolution.
3. A few Gauss-Newton steps on the bilinearly interpolated field (as Hector
   SLAM does) move the pose below the grid's cell.

The score is the mean likelihood over the scan's points (0 to 1): the share of
points that land on the reference, softened by ``sigma_m``. The covariance
comes from the response around the best pose (Olson section IV: the poses
evaluated, weighted by their likelihood), floored at the search's resolution.
Everything is in SI: metres and radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

Pose2 = tuple[float, float, float]
"""A 2D pose (x m, y m, yaw rad)."""


@dataclass(frozen=True)
class MatcherConfig:
    """The knobs of the correlative scan matcher (metres, radians).

    ``resolution_m`` the likelihood field's cell (finer is more exact and
    slower); ``sigma_m`` how far off a wall a point still scores (the LiDAR's
    noise plus the map's blur); ``window_xy_m`` / ``window_yaw_rad`` the
    half-widths of the search around the prior; ``yaw_step_rad`` the heading
    step (a point 4 m away moves ``4 * step`` per step); ``coarse_factor`` fine
    cells per coarse cell; ``max_points`` the scan is thinned to about this
    many points (spread evenly) before matching; ``refine_iterations``
    Gauss-Newton steps after the search (0: none).
    """

    resolution_m: float = 0.025
    sigma_m: float = 0.05
    window_xy_m: float = 0.3
    window_yaw_rad: float = math.radians(12.0)
    yaw_step_rad: float = math.radians(0.5)
    coarse_factor: int = 4
    max_points: int = 500
    refine_iterations: int = 8


@dataclass(frozen=True)
class MatchResult:
    """The outcome of one match: the pose of the scan's base_link in the reference frame (m, rad), its 3x3
    covariance over (x, y, yaw) (m^2, rad^2), the score (mean likelihood over the points, 0 to 1) and how many
    points took part."""

    pose: Pose2
    covariance: np.ndarray
    score: float
    points: int


def wrap(angle: float) -> float:
    """``angle`` (rad) wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def transform_points(points: np.ndarray, pose: Pose2) -> np.ndarray:
    """Points (n, 2) in a body frame moved into the frame where the body sits at ``pose``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    out = np.empty_like(points, dtype=float)
    out[:, 0] = c * points[:, 0] - s * points[:, 1] + pose[0]
    out[:, 1] = s * points[:, 0] + c * points[:, 1] + pose[1]
    return out


def thin_points(points: np.ndarray, spacing_m: float, max_points: int) -> np.ndarray:
    """At most ``max_points`` of ``points`` (n, 2), first one per ``spacing_m`` cell (a wall close by gives many
    points, a far one few: thinning by cell keeps both), then evenly spread."""
    if len(points) == 0:
        return points
    cells = np.floor(points / spacing_m).astype(np.int64)
    _, keep = np.unique(cells[:, 0] * 1_000_003 + cells[:, 1], return_index=True)
    keep.sort()
    points = points[keep]
    if len(points) > max_points:
        points = points[np.linspace(0, len(points) - 1, max_points).astype(np.intp)]
    return points


class LikelihoodField:
    """The reference points drawn into a grid and blurred by a Gaussian of the distance to the nearest one.

    ``origin`` is the map-frame position (m) of cell (0, 0)'s lower-left
    corner, ``values[row, col]`` the likelihood (0..1, float32), ``upper``
    its max over the next ``coarse_factor`` cells in x and y (the coarse
    level's upper bound).
    """

    def __init__(self, points: np.ndarray, config: MatcherConfig, margin_m: float) -> None:
        import cv2  # OpenCV's distance transform and max filter: exact and fast

        res = config.resolution_m
        lo = points.min(axis=0) - margin_m
        hi = points.max(axis=0) + margin_m
        self.origin = lo
        self.resolution_m = res
        self.cols = int(math.ceil((hi[0] - lo[0]) / res)) + 1
        self.rows = int(math.ceil((hi[1] - lo[1]) / res)) + 1
        free = np.full((self.rows, self.cols), 255, dtype=np.uint8)
        col = np.floor((points[:, 0] - lo[0]) / res).astype(np.intp)
        row = np.floor((points[:, 1] - lo[1]) / res).astype(np.intp)
        free[row, col] = 0
        dist = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * res
        self.values = np.exp(-(dist * dist) / (2.0 * config.sigma_m ** 2)).astype(np.float32)
        k = config.coarse_factor
        # A max filter whose window starts at the cell itself: upper[r, c] = max(values[r:r+k, c:c+k]).
        padded = np.pad(self.values, ((0, k), (0, k)))
        dilated = cv2.dilate(padded, np.ones((k, k), np.uint8), anchor=(0, 0), borderType=cv2.BORDER_CONSTANT,
                             borderValue=0)
        self.upper = dilated[: self.rows, : self.cols]
        self._flat = self.values.ravel()
        self._flat_upper = self.upper.ravel()

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map-frame points (n, 2) to integer (col, row) cells of the field (may lie outside)."""
        res = self.resolution_m
        return (np.floor((xy[:, 0] - self.origin[0]) / res).astype(np.intp),
                np.floor((xy[:, 1] - self.origin[1]) / res).astype(np.intp))

    def scores(self, col: np.ndarray, row: np.ndarray, dc: np.ndarray, dr: np.ndarray,
               upper: bool = False) -> np.ndarray:
        """Mean likelihood of points at cells (col, row) (n,) shifted by each offset (dc, dr) (m,): shape (m,)."""
        c = col[None, :] + dc[:, None]
        r = row[None, :] + dr[:, None]
        inside = (c >= 0) & (c < self.cols) & (r >= 0) & (r < self.rows)
        flat = np.where(inside, r * self.cols + c, 0)
        table = self._flat_upper if upper else self._flat
        vals = np.where(inside, table[flat], 0.0)
        return vals.mean(axis=1)

    def sample(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bilinear likelihood at map-frame points (n, 2) and its gradient (per metre): (value, d/dx, d/dy)."""
        res = self.resolution_m
        u = (xy[:, 0] - self.origin[0]) / res - 0.5  # cell centres at integer u, v
        v = (xy[:, 1] - self.origin[1]) / res - 0.5
        c0 = np.floor(u).astype(np.intp)
        r0 = np.floor(v).astype(np.intp)
        fu, fv = u - c0, v - r0
        ok = (c0 >= 0) & (c0 < self.cols - 1) & (r0 >= 0) & (r0 < self.rows - 1)
        c0, r0 = np.where(ok, c0, 0), np.where(ok, r0, 0)
        g = self.values
        p00, p10, p01, p11 = g[r0, c0], g[r0, c0 + 1], g[r0 + 1, c0], g[r0 + 1, c0 + 1]
        value = (1 - fv) * ((1 - fu) * p00 + fu * p10) + fv * ((1 - fu) * p01 + fu * p11)
        ddu = (1 - fv) * (p10 - p00) + fv * (p11 - p01)
        ddv = (1 - fu) * (p01 - p00) + fu * (p11 - p10)
        return np.where(ok, value, 0.0), np.where(ok, ddu / res, 0.0), np.where(ok, ddv / res, 0.0)


class ScanMatcher:
    """Correlative scan matching of base_link points against reference points (see the module's docstring)."""

    def __init__(self, config: Optional[MatcherConfig] = None) -> None:
        self.config = config if config is not None else MatcherConfig()

    def field(self, reference_xy: np.ndarray, window_xy_m: Optional[float] = None) -> LikelihoodField:
        """The likelihood field of reference points (n, 2; map frame, m), with room for a search ``window_xy_m``."""
        window = self.config.window_xy_m if window_xy_m is None else window_xy_m
        return LikelihoodField(reference_xy, self.config, margin_m=window + 4 * self.config.sigma_m)

    def match(self, scan_xy: np.ndarray, reference: LikelihoodField, prior: Pose2,
              window_xy_m: Optional[float] = None, window_yaw_rad: Optional[float] = None) -> Optional[MatchResult]:
        """The pose of ``scan_xy`` (n, 2 base_link points, m) on ``reference`` searched around ``prior`` (x, y m,
        yaw rad) within the windows (half-widths; the config's by default); None without points to match."""
        cfg = self.config
        wxy = cfg.window_xy_m if window_xy_m is None else window_xy_m
        wyaw = cfg.window_yaw_rad if window_yaw_rad is None else window_yaw_rad
        pts = thin_points(np.asarray(scan_xy, dtype=float), cfg.resolution_m * 2, cfg.max_points)
        if len(pts) < 10:
            return None
        res, k = cfg.resolution_m, cfg.coarse_factor
        n_fine = int(math.ceil(wxy / res))
        n_coarse = int(math.ceil(n_fine / k))
        coarse = np.arange(-n_coarse, n_coarse + 1) * k
        cdc, cdr = (a.ravel() for a in np.meshgrid(coarse, coarse))
        sub = np.arange(k)
        fdc, fdr = (a.ravel() for a in np.meshgrid(sub, sub))
        n_yaw = int(math.ceil(wyaw / cfg.yaw_step_rad))
        yaws = prior[2] + np.arange(-n_yaw, n_yaw + 1) * cfg.yaw_step_rad

        # Coarse level: every heading, every coarse translation, scored with the upper bound.
        per_yaw = []
        bounds = np.empty((len(yaws), len(cdc)))
        for i, yaw in enumerate(yaws):
            xy = transform_points(pts, (prior[0], prior[1], float(yaw)))
            col, row = reference.cells(xy)
            per_yaw.append((col, row))
            bounds[i] = reference.scores(col, row, cdc, cdr, upper=True)
        order = np.argsort(-bounds, axis=None, kind="stable")
        # (upper bound, yaw index, coarse offset index), best first
        candidates = zip(bounds.ravel()[order].tolist(), *(a.tolist() for a in np.unravel_index(order, bounds.shape)))

        # Fine level, best coarse candidate first, until no upper bound can beat the best fine score.
        best = (-1.0, 0, 0, 0)
        evaluated = []  # (score, yaw, dc, dr) of every fine pose scored: the response for the covariance
        for bound, i, j in candidates:
            if bound <= best[0]:
                break
            col, row = per_yaw[i]
            dc, dr = cdc[j] + fdc, cdr[j] + fdr
            s = reference.scores(col, row, dc, dr)
            m = int(np.argmax(s))
            evaluated.append((s, i, dc, dr))
            if s[m] > best[0]:
                best = (float(s[m]), i, int(dc[m]), int(dr[m]))
        score, i, dc_best, dr_best = best
        # The grid offsets are whole cells from each point's own cell: the same shift of the pose in metres.
        pose = (prior[0] + dc_best * res, prior[1] + dr_best * res, float(yaws[i]))
        pose = self.refine(pts, reference, pose, wxy, wyaw, prior)
        final = float(reference.sample(transform_points(pts, pose))[0].mean())
        if final < score:  # the refinement did not help (a flat or odd field): keep the searched pose
            pose = (prior[0] + dc_best * res, prior[1] + dr_best * res, float(yaws[i]))
            final = score
        cov = self._covariance(evaluated, yaws, prior, score, len(pts))
        return MatchResult(pose, cov, final, len(pts))

    def refine(self, pts: np.ndarray, reference: LikelihoodField, pose: Pose2, wxy: float, wyaw: float,
               prior: Pose2) -> Pose2:
        """Gauss-Newton on ``sum (1 - L(T(pose) p))^2`` over the bilinear field (Hector SLAM's step), kept
        within the search window around ``prior``."""
        x, y, t = pose
        for _ in range(self.config.refine_iterations):
            c, s = math.cos(t), math.sin(t)
            xy = transform_points(pts, (x, y, t))
            val, gx, gy = reference.sample(xy)
            # d(point)/d(yaw) = R'(t) p
            dtx = -s * pts[:, 0] - c * pts[:, 1]
            dty = c * pts[:, 0] - s * pts[:, 1]
            j = np.column_stack((gx, gy, gx * dtx + gy * dty))
            r = 1.0 - val
            h = j.T @ j + np.diag((1e-6, 1e-6, 1e-6))
            try:
                step = np.linalg.solve(h, j.T @ r)
            except np.linalg.LinAlgError:
                break
            x, y, t = x + step[0], y + step[1], t + step[2]
            if float(np.abs(step[:2]).max()) < 1e-4 and abs(step[2]) < 1e-5:
                break
        if abs(x - prior[0]) > wxy or abs(y - prior[1]) > wxy or abs(wrap(t - prior[2])) > wyaw:
            return pose
        return (float(x), float(y), float(t))

    def _covariance(self, evaluated: list, yaws: np.ndarray, prior: Pose2, best: float, n: int) -> np.ndarray:
        """Olson's covariance: the fine poses scored, weighted by ``exp(n (s - best) / 2)`` (the scores as a
        log-likelihood of the points), floored at the grid's resolution and the heading step."""
        cfg = self.config
        res = cfg.resolution_m
        poses, weights = [], []
        for s, i, dc, dr in evaluated:
            w = np.exp(0.5 * n * (s - best))
            keep = w > 1e-4
            if np.any(keep):
                poses.append(np.column_stack((dc[keep] * res, dr[keep] * res, np.full(int(keep.sum()), yaws[i]))))
                weights.append(w[keep])
        floor = np.diag((res ** 2, res ** 2, cfg.yaw_step_rad ** 2))
        if not poses:
            return floor
        p = np.concatenate(poses)
        w = np.concatenate(weights)
        w = w / w.sum()
        mean = (p * w[:, None]).sum(axis=0)
        d = p - mean
        return (d * w[:, None]).T @ d + floor


__all__ = ["ScanMatcher", "MatcherConfig", "MatchResult", "LikelihoodField", "Pose2", "transform_points",
           "thin_points", "wrap"]
