"""Line detection: where the painted line is relative to the robot, and what is on it.

:class:`LineDetector` turns one camera image into a
:class:`~beastbt.blackboard.types.LineObservation` in the robot body frame
(x forward, y left, metres from the robot centre; angles CCW):

1. **Bird's-eye view.** The image (downsampled to ``process_width_px``) is
   warped, through :class:`~beastbt.vision.camera_model.CameraGeometry`,
   onto a small metric grid of the floor ahead (``grid_resolution_m`` per
   cell, ``roi_*`` bounds). From here on the line has the same width
   everywhere, angles are true and every distance is in metres.
2. **Segmentation.** ``dark_on_light`` (``light_on_dark`` inverts first):
   highlights are clipped to ``highlight_clip`` x the median floor (glare),
   the local floor brightness is estimated by a morphological closing wider
   than the line (it follows lighting gradients and shadow edges but not the
   thin line), and a cell is "line" when it is darker than that by
   ``contrast_ratio`` (relative, so it holds in shadow) and by
   ``min_contrast`` grey levels. ``colour`` thresholds HSV instead.
3. **Bands.** The grid is cut into horizontal bands ``band_height_m`` tall
   (constant distance ahead). Each band's dark runs give line candidates
   with centre and width in metres. The line is tracked band by band from
   the nearest, following the run closest to the prediction; gaps up to
   ``max_gap_m`` are bridged, bands where the run is much wider than the
   line (a crossing or branch) are passed through on the prediction.
4. **Fit.** A straight line through the tracked centres within
   ``fit_window_m`` of ``lookahead_m`` gives ``offset_m`` (at the look-ahead,
   +left) and ``angle_rad`` (+CCW).
5. **Junctions.** Around each tracked centre, a ring of radius
   ``junction_radius_m`` is sampled; the number of dark arcs it crosses is
   the number of arms meeting nearby (2 on a line or a bend, 3 at a T or Y,
   4 at a crossing). At ``junction_min_hits`` consecutive rings with 3 or
   more arms, the arcs are grouped into arms, a line is fitted through each
   arm's ring crossings, and the point nearest to all arm lines is the
   junction centre: its forward coordinate is ``intersection_distance_m``,
   measured from the robot centre (the kind, ``+``/``T``/``Y``, comes from
   the arms' directions, see :func:`junction_kind`). With the default
   mounting a junction is reported from about 0.75 m down to 0.25 m ahead;
   after that it is under the camera and a follower must finish on odometry.
6. **Line end.** The track stops (gap longer than ``max_gap_m``) inside the
   view, with no junction there.

Costs about half a millisecond per frame at 320x240 on a desktop core; the
work is on the fixed-size grid, so larger images only add the downsampling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal, Optional, Sequence

import cv2
import numpy as np

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import LineObservation
from beastbt.core.config import dataclass_from_dict
from beastbt.vision.camera_model import CameraGeometry

RING_SAMPLES = 64
"""Points sampled on each junction ring (5.6 deg apart: a 19 mm line at 5 cm spans about 4)."""

START_SEARCH_M = 0.15
"""The line must be found within this distance beyond the nearest band examined, metres."""

MAX_START_TRIES = 3
"""Start candidates tried before giving up on a frame (the first that yields a long enough line wins)."""

GLARE_REACH_M = 0.03
"""Tape this close to a clipped highlight counts as lost in glare, metres."""

GLARE_GAP_WEIGHT = 0.25
"""A band lost in glare counts as this fraction of a band towards ``max_gap_m``."""


@dataclass
@schema_defaults("parts/line_detector.schema.json")
class LineDetectorConfig:
    """Knobs of the line detector (robot profile ``line_detector:``)."""

    # What the line looks like: "dark_on_light" (black tape on a light floor),
    # "light_on_dark" (white tape on a dark floor) or "colour" (hsv_low..hsv_high).
    mode: Literal["dark_on_light", "light_on_dark", "colour"]
    # HSV range for mode "colour", OpenCV scale (H 0-179, S and V 0-255). Default: yellow tape.
    hsv_low: list
    hsv_high: list
    # Wider images are downsampled (area average) to this width first, pixels; 0 = never.
    # The bird's-eye grid below is coarser than 320 px anyway.
    process_width_px: int
    # Cell size of the bird's-eye floor grid, metres. Keep it <= a third of the line width.
    grid_resolution_m: float
    # Nearest floor examined, metres ahead of the robot centre; null = just inside the
    # nearest floor the camera sees.
    roi_near_m: Optional[float]
    # Farthest floor examined, metres ahead of the robot centre (capped by what the camera sees).
    roi_far_m: float
    # Half width of the examined floor strip, metres to each side of the robot's centreline.
    roi_half_width_m: float
    # Height of one band (a strip of constant distance ahead), metres.
    band_height_m: float
    # Size of the local-floor-brightness window, metres; must exceed about twice the
    # line width (or the line counts as floor) but stay below shadow/lighting detail.
    background_kernel_m: float
    # A line cell is at least this fraction darker than its local floor (0.6 = 60 %).
    # Keep it above the darkness of the deepest shadow (a narrow shadow looks like a
    # line) and below the tape's: black tape on a light floor is about 0.85. Lower it
    # for grey or faded tape.
    contrast_ratio: float
    # ... and at least this many grey levels darker (guards against noise in dark areas).
    min_contrast: float
    # Brightness above this multiple of the median floor is clipped (glare); 0 = off.
    highlight_clip: float
    # Expected true line width range, metres. Runs outside it are not taken for the line.
    line_width_min_m: float
    line_width_max_m: float
    # Distance ahead of the robot centre at which offset_m and angle_rad are reported, metres.
    lookahead_m: float
    # Tracked centres within this distance of the look-ahead are fitted, metres.
    fit_window_m: float
    # Longest stretch without line that is bridged (worn tape, glare), metres.
    max_gap_m: float
    # Radius of the ring that counts the arms of a junction, metres (about 2.5 line widths,
    # at least line_width_max_m).
    junction_radius_m: float
    # Consecutive rings (one per band) that must see 3+ arms before a junction is reported.
    junction_min_hits: int
    # Observations below this confidence (0-1) are reported as not seen.
    min_confidence: float
    # Shortest tracked stretch of line that counts as seeing it, metres.
    min_line_length_m: float

    def __post_init__(self) -> None:
        for name in ("hsv_low", "hsv_high"):
            v = getattr(self, name)
            if not isinstance(v, (list, tuple)) or len(v) != 3 or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255 for c in v):
                raise ValueError(f"line_detector.{name} must be three integers [h, s, v] in 0..255, got {v!r}")
        if self.process_width_px != 0 and self.process_width_px < 32:
            raise ValueError(f"line_detector.process_width_px must be 0 or >= 32, got {self.process_width_px}")
        if not 0.001 <= self.grid_resolution_m <= 0.05:
            raise ValueError(f"line_detector.grid_resolution_m must be in [0.001, 0.05] m, got {self.grid_resolution_m}")
        if self.roi_near_m is not None and not 0.0 <= self.roi_near_m < self.roi_far_m:
            raise ValueError(f"line_detector.roi_near_m must be in [0, roi_far_m), got {self.roi_near_m}")
        if not 0.05 <= self.roi_far_m <= 10.0:
            raise ValueError(f"line_detector.roi_far_m must be in [0.05, 10] m, got {self.roi_far_m}")
        if not 0.02 <= self.roi_half_width_m <= 5.0:
            raise ValueError(f"line_detector.roi_half_width_m must be in [0.02, 5] m, got {self.roi_half_width_m}")
        if not self.grid_resolution_m <= self.band_height_m <= 0.1:
            raise ValueError(f"line_detector.band_height_m must be in [grid_resolution_m, 0.1] m, got {self.band_height_m}")
        if not 0.0 < self.contrast_ratio < 1.0:
            raise ValueError(f"line_detector.contrast_ratio must be in (0, 1), got {self.contrast_ratio}")
        if not 0.0 <= self.min_contrast <= 255.0:
            raise ValueError(f"line_detector.min_contrast must be in [0, 255], got {self.min_contrast}")
        if self.highlight_clip != 0.0 and self.highlight_clip < 1.0:
            raise ValueError(f"line_detector.highlight_clip must be 0 (off) or >= 1, got {self.highlight_clip}")
        if not 0.0 < self.line_width_min_m < self.line_width_max_m:
            raise ValueError("line_detector.line_width_min_m must be > 0 and < line_width_max_m")
        if self.background_kernel_m < 1.5 * self.line_width_max_m:
            raise ValueError(f"line_detector.background_kernel_m must be at least 1.5 x line_width_max_m ({1.5 * self.line_width_max_m:g} m)")
        if not 0.0 < self.lookahead_m <= 10.0:
            raise ValueError(f"line_detector.lookahead_m must be in (0, 10] m, got {self.lookahead_m}")
        if not 0.01 <= self.fit_window_m <= 2.0:
            raise ValueError(f"line_detector.fit_window_m must be in [0.01, 2] m, got {self.fit_window_m}")
        if not 0.0 <= self.max_gap_m <= 1.0:
            raise ValueError(f"line_detector.max_gap_m must be in [0, 1] m, got {self.max_gap_m}")
        if not self.line_width_max_m <= self.junction_radius_m <= 0.5:
            raise ValueError(f"line_detector.junction_radius_m must be in [line_width_max_m, 0.5] m, got {self.junction_radius_m}")
        if self.junction_min_hits < 1:
            raise ValueError(f"line_detector.junction_min_hits must be >= 1, got {self.junction_min_hits}")
        if not 0.0 <= self.min_confidence <= 1.0:
            raise ValueError(f"line_detector.min_confidence must be in [0, 1], got {self.min_confidence}")
        if not 0.0 <= self.min_line_length_m <= 2.0:
            raise ValueError(f"line_detector.min_line_length_m must be in [0, 2] m, got {self.min_line_length_m}")

    @classmethod
    def from_dict(cls, d: Any) -> "LineDetectorConfig":
        """Build from a profile dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "line_detector")


def junction_kind(arm_angles_rad: Sequence[float]) -> Optional[str]:
    """Junction kind from the directions (rad) of the arms that meet: ``+``, ``T``, ``Y`` or None.

    4 or more arms: ``+``. 3 arms: ``T`` when two are opposite (within 20 deg)
    and the third is square to them (within 25 deg), else ``Y``. Fewer arms
    (a line, a bend, an end) are not a junction.
    """
    n = len(arm_angles_rad)
    if n >= 4:
        return "+"
    if n != 3:
        return None
    for k in range(3):
        a, b, c = arm_angles_rad[k], arm_angles_rad[(k + 1) % 3], arm_angles_rad[(k + 2) % 3]
        if abs(abs(math.remainder(a - b, 2 * math.pi)) - math.pi) < math.radians(20):
            if abs(abs(math.remainder(c - a, 2 * math.pi)) - math.pi / 2) < math.radians(25):
                return "T"
    return "Y"


@dataclass
class LineDetection:
    """Everything one :meth:`LineDetector.detect` call found (for overlays, logs and tests).

    Points are body-frame metres (x forward, y left from the robot centre).
    """

    observation: LineObservation
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    """Tracked line centres (N, 2), nearest first."""
    intersection_kind: Optional[str] = None
    """``+``, ``T`` or ``Y`` when an intersection is in view."""
    intersection_xy: Optional[tuple[float, float]] = None
    """Where the junction centre is, metres."""
    end_xy: Optional[tuple[float, float]] = None
    """Where the line ends, when it ends in view."""
    stop_reason: str = ""
    """Why tracking stopped: ``far`` (top of the view), ``side`` (left the view), ``gap``, ``none`` (no line)."""


@dataclass
class _Track:
    """One attempt at following the line: accepted centres, ring centres and why it stopped."""

    pts_x: list
    pts_y: list
    pts_w: list
    pts_b: list
    ring_x: list
    ring_y: list
    stop: str
    last_b: int
    b0: int
    slope: float

    @property
    def length(self) -> float:
        """Forward extent of the accepted centres, metres."""
        return self.pts_x[-1] - self.pts_x[0] if len(self.pts_x) > 1 else 0.0


class _Setup:
    """Everything that depends only on the image size: geometry, grid warp, masks, ring offsets."""

    def __init__(self, cfg: LineDetectorConfig, geometry: CameraGeometry, in_w: int, in_h: int) -> None:
        if cfg.process_width_px and in_w > cfg.process_width_px:
            self.proc_w = cfg.process_width_px
            self.proc_h = max(2, int(round(in_h * cfg.process_width_px / in_w)))
        else:
            self.proc_w, self.proc_h = in_w, in_h
        geom = geometry.scaled_to(self.proc_w, self.proc_h)
        self.geometry = geom
        res = cfg.grid_resolution_m
        self.res = res
        near = cfg.roi_near_m
        if near is None:
            nearest = geom.nearest_visible_x_m()
            near = (nearest if nearest is not None else 0.0) + 2 * res
        far = cfg.roi_far_m
        top = geom.pixel_to_ground((self.proc_w - 1) / 2.0, 0.0)
        if top is not None:
            far = min(far, top[0])
        if far <= near + 4 * cfg.band_height_m:
            raise ValueError(f"the camera sees too little floor between {near:.3f} m and {far:.3f} m ahead for line detection; check its mounting")
        self.band_rows = max(1, int(round(cfg.band_height_m / res)))
        self.n_rows = int(math.floor((far - near) / res)) + 1
        self.n_rows -= self.n_rows % self.band_rows
        self.n_bands = self.n_rows // self.band_rows
        self.n_cols = int(math.floor(2 * cfg.roi_half_width_m / res)) + 1
        self.x_far = near + (self.n_rows - 1) * res
        self.y_left = (self.n_cols - 1) * res / 2.0
        # grid cell (col j, row i) -> body (x, y): x = x_far - i res, y = y_left - j res
        self.body_from_grid = np.array([[0.0, -res, self.x_far], [-res, 0.0, self.y_left], [0.0, 0.0, 1.0]])
        self.image_from_grid = geom.image_from_ground @ self.body_from_grid
        # Cells whose floor the camera really sees (one pixel inside the border).
        jj, ii = np.meshgrid(np.arange(self.n_cols), np.arange(self.n_rows))
        xy = np.column_stack([(self.x_far - ii * res).ravel(), (self.y_left - jj * res).ravel()])
        uv = geom.ground_to_pixels(xy)
        inside = (uv[:, 0] >= 1) & (uv[:, 0] <= self.proc_w - 2) & (uv[:, 1] >= 1) & (uv[:, 1] <= self.proc_h - 2)
        self.valid = inside.reshape(self.n_rows, self.n_cols)
        self.valid_u8 = self.valid.astype(np.uint8) * 255
        self.valid_idx = np.flatnonzero(self.valid.ravel()[:: 7])  # a sample for the median brightness
        k = max(3, int(round(cfg.background_kernel_m / res)) | 1)
        self.bg_kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (k, k))
        self.glare_reach = max(1, int(round(GLARE_REACH_M / res)))
        self.open_kernel = np.ones((3, 3), np.uint8) if cfg.line_width_min_m / res >= 3 else None
        # Bands, nearest first: band b is grid rows [n_rows - (b+1) band_rows, n_rows - b band_rows).
        rows_x = self.x_far - np.arange(self.n_rows) * res
        self.band_x = rows_x[::-1].reshape(self.n_bands, self.band_rows).mean(axis=1)
        band_valid = self.valid[::-1].reshape(self.n_bands, self.band_rows, self.n_cols).all(axis=1)
        y_cols = self.y_left - np.arange(self.n_cols) * res
        self.band_y_lo = []  # rightmost valid y per band (most negative)
        self.band_y_hi = []
        for b in range(self.n_bands):
            cols = np.flatnonzero(band_valid[b])
            if len(cols):
                self.band_y_hi.append(float(y_cols[cols[0]]))
                self.band_y_lo.append(float(y_cols[cols[-1]]))
            else:
                self.band_y_hi.append(-math.inf)
                self.band_y_lo.append(math.inf)
        phi = np.arange(RING_SAMPLES) * (2 * math.pi / RING_SAMPLES)
        self.ring_phi = phi
        r_px = cfg.junction_radius_m / res
        self.ring_di = -r_px * np.cos(phi)  # forward = up the grid (row index decreases)
        self.ring_dj = -r_px * np.sin(phi)  # left = column index decreases


class LineDetector:
    """Finds the line in camera images; one instance per camera, it remembers the last line seen.

    ``geometry`` describes the camera that took the images (any image size
    with the same field of view is accepted: the geometry is rescaled).
    """

    def __init__(self, config: Optional[LineDetectorConfig] = None, geometry: Optional[CameraGeometry] = None) -> None:
        self.config = config if config is not None else LineDetectorConfig()
        self.geometry = geometry if geometry is not None else CameraGeometry()
        self._setups: dict[tuple[int, int], _Setup] = {}
        self._hint_y = 0.0  # where the line crossed the nearest band last time, metres
        self._hint_slope = 0.0  # dy/dx there
        self._misses = 0
        self._darkness: Optional[np.ndarray] = None  # how much darker than the floor each grid cell is
        self._glare: Optional[np.ndarray] = None  # grid cells whose brightness was clipped
        self.last: Optional[LineDetection] = None
        """The full result of the last :meth:`detect` call."""

    def reset(self) -> None:
        """Forget the previous line position (e.g. after a turn onto a new branch)."""
        self._hint_y = 0.0
        self._hint_slope = 0.0
        self._misses = 0

    def _setup(self, w: int, h: int) -> _Setup:
        s = self._setups.get((w, h))
        if s is None:
            s = self._setups[(w, h)] = _Setup(self.config, self.geometry, w, h)
        return s

    # --- the pipeline -------------------------------------------------------------------
    def detect(self, image: np.ndarray, stamp_s: float) -> LineObservation:
        """Find the line in a BGR (or grey) uint8 image taken at ``stamp_s`` seconds."""
        return self.detect_full(image, stamp_s).observation

    def detect_full(self, image: np.ndarray, stamp_s: float) -> LineDetection:
        """Like :meth:`detect` but returns the whole :class:`LineDetection`."""
        h, w = image.shape[:2]
        s = self._setup(w, h)
        mask = self._segment(image, s)
        det = self._track(mask, s, stamp_s)
        self.last = det
        return det

    def line_mask(self, image: np.ndarray) -> np.ndarray:
        """The bird's-eye grid's line cells (uint8 0/255; row 0 farthest, column 0 leftmost), for inspection."""
        h, w = image.shape[:2]
        return self._segment(image, self._setup(w, h))

    def _segment(self, image: np.ndarray, s: _Setup) -> np.ndarray:
        """Bird's-eye warp and thresholding: uint8 mask (255 = line) of the floor grid."""
        cfg = self.config
        img = image
        if img.shape[1] != s.proc_w:
            img = cv2.resize(img, (s.proc_w, s.proc_h), interpolation=cv2.INTER_AREA)
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        size = (s.n_cols, s.n_rows)
        self._darkness = None
        self._glare = None
        if cfg.mode == "colour":
            if img.ndim == 2:
                return np.zeros((s.n_rows, s.n_cols), np.uint8)
            top = cv2.warpPerspective(img, s.image_from_grid, size, flags=flags, borderMode=cv2.BORDER_REPLICATE)
            hsv = cv2.cvtColor(top, cv2.COLOR_BGR2HSV)
            mask = cv2.inRange(hsv, np.array(cfg.hsv_low, np.uint8), np.array(cfg.hsv_high, np.uint8))
        else:
            gray = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
            if cfg.mode == "light_on_dark":
                gray = cv2.bitwise_not(gray)
            top = cv2.warpPerspective(gray, s.image_from_grid, size, flags=flags, borderMode=cv2.BORDER_REPLICATE)
            if cfg.highlight_clip > 0 and len(s.valid_idx):
                median = float(np.median(top.ravel()[::7][s.valid_idx]))
                clip = min(255, int(median * cfg.highlight_clip + 0.5))
                self._glare = top >= clip
                np.minimum(top, clip, out=top)
            # Closing removes dark structures thinner than the kernel: what is left is the
            # floor's own brightness, gradients and shadows included.
            floor_level = cv2.morphologyEx(top, cv2.MORPH_CLOSE, s.bg_kernel)
            darkness = cv2.subtract(floor_level, top)
            need = cv2.convertScaleAbs(floor_level, alpha=cfg.contrast_ratio)
            np.maximum(need, np.uint8(min(255, int(cfg.min_contrast))), out=need)
            mask = cv2.compare(darkness, need, cv2.CMP_GT)
            self._darkness = darkness
        cv2.bitwise_and(mask, s.valid_u8, dst=mask)
        if s.open_kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, s.open_kernel)
        return mask

    def _band_runs(self, mask: np.ndarray, s: _Setup) -> list[list[tuple[float, float]]]:
        """Dark runs per band, nearest band first: lists of (centre y, width) in metres."""
        bands = mask[::-1].reshape(s.n_bands, s.band_rows, s.n_cols).max(axis=1)
        padded = np.zeros((s.n_bands, s.n_cols + 2), np.int8)
        padded[:, 1:-1] = bands > 0
        d = np.diff(padded, axis=1)
        rs, cs = np.nonzero(d == 1)
        _, ce = np.nonzero(d == -1)
        yc = s.y_left - (cs + ce - 1) * (s.res / 2.0)
        wd = (ce - cs) * s.res
        runs: list[list[tuple[float, float]]] = [[] for _ in range(s.n_bands)]
        for b, y, ww in zip(rs.tolist(), yc.tolist(), wd.tolist()):
            runs[b].append((y, ww))
        return runs

    def _start_candidates(self, runs: list[list[tuple[float, float]]], s: _Setup) -> list[tuple[int, float, float]]:
        """Where the line may start: (band, y, width) of plausible runs in the nearest bands.

        Ordered by band (nearest first), then by distance from where the line was
        last time. Runs cut by the edge of the view come last (a bar cut at the
        view's corner looks like a narrow line there).
        """
        cfg = self.config
        bx = s.band_x
        out = []
        for b in range(s.n_bands):
            if bx[b] > bx[0] + START_SEARCH_M:
                break
            pred = self._hint_y + self._hint_slope * (bx[b] - bx[0])
            for y, w in runs[b]:
                if 0.75 * cfg.line_width_min_m <= w <= 3.0 * cfg.line_width_max_m:
                    at_edge = y + 0.5 * w >= s.band_y_hi[b] - s.res or y - 0.5 * w <= s.band_y_lo[b] + s.res
                    out.append((int(at_edge), b, abs(y - pred), y, w))
        out.sort()
        return [(b, y, w) for _, b, _, y, w in out]

    def _track(self, mask: np.ndarray, s: _Setup, stamp_s: float) -> LineDetection:
        cfg = self.config
        runs = self._band_runs(mask, s)
        best_follow = None
        for start in self._start_candidates(runs, s)[:MAX_START_TRIES]:
            follow = self._follow(runs, s, start)
            if best_follow is None or follow.length > best_follow.length:
                best_follow = follow
            if follow.length >= cfg.min_line_length_m:
                break
        if best_follow is None:
            return self._lost(stamp_s)
        return self._conclude(mask, s, best_follow, stamp_s)

    def _follow(self, runs: list[list[tuple[float, float]]], s: _Setup, start: tuple[int, float, float]) -> "_Track":
        """Follow the line band by band from ``start`` (band, y, width) as far as it goes."""
        cfg = self.config
        bx = s.band_x.tolist()
        w_mid = 0.5 * (cfg.line_width_min_m + cfg.line_width_max_m)
        b0, y0, w0 = start
        slope = self._hint_slope if self._misses < 3 else 0.0
        w_est = min(max(w0 / math.sqrt(1 + slope * slope), cfg.line_width_min_m), cfg.line_width_max_m) if w0 else w_mid
        pts_x, pts_y, pts_w, pts_b = [bx[b0]], [y0], [w0], [b0]
        ring_x, ring_y = [bx[b0]], [y0]  # junction ring centres: accepted and bridged bands
        gap, wide_run = 0.0, 0.0
        stop = "far"
        band_h = cfg.band_height_m
        last_b = b0
        for b in range(b0 + 1, s.n_bands):
            x = bx[b]
            pred = pts_y[-1] + slope * (x - pts_x[-1])
            if not (s.band_y_lo[b] + 0.5 * w_est <= pred <= s.band_y_hi[b] - 0.5 * w_est):
                stop = "side"
                break
            row_w = w_est * math.sqrt(1 + slope * slope)
            gate = max(0.03, 1.5 * row_w)
            best, best_d = None, gate
            for r in runs[b]:
                d = max(0.0, abs(r[0] - pred) - 0.5 * r[1])  # distance from the prediction to the run
                if d < best_d:
                    best, best_d = r, d
            if best is None:
                # Glare washes tape out over a longer stretch than wear does: bridge more of it.
                gap += band_h * (GLARE_GAP_WEIGHT if self._in_glare(s, b, pred) else 1.0)
                if gap > cfg.max_gap_m:
                    stop = "gap"
                    break
                ring_x.append(x)
                ring_y.append(pred)
                continue
            if best[1] > 1.8 * row_w + 2 * s.res:
                # a crossing, a branch or the line turning along the band: ride the prediction
                wide_run += band_h
                if wide_run > 0.12:
                    stop = "wide"
                    break
                ring_x.append(x)
                ring_y.append(pred)
                gap = 0.0
                continue
            gap, wide_run = 0.0, 0.0
            pts_x.append(x)
            pts_y.append(best[0])
            pts_w.append(best[1])
            pts_b.append(b)
            ring_x.append(x)
            ring_y.append(best[0])
            last_b = b
            # slope from the centres over the last ~4 cm (enough to average pixel steps)
            k = len(pts_x) - 1
            j = k
            while j > 0 and pts_x[k] - pts_x[j - 1] <= 0.04 + 1e-9:
                j -= 1
            if k - j >= 2:
                new = (pts_y[k] - pts_y[j]) / (pts_x[k] - pts_x[j])
                slope = new if len(pts_x) > 4 else 0.5 * (slope + new)
            w_est = 0.8 * w_est + 0.2 * min(max(best[1] / math.sqrt(1 + slope * slope), cfg.line_width_min_m), cfg.line_width_max_m)
        return _Track(pts_x, pts_y, pts_w, pts_b, ring_x, ring_y, stop, last_b, b0, slope)

    def _conclude(self, mask: np.ndarray, s: _Setup, t: "_Track", stamp_s: float) -> LineDetection:
        """Fit, junctions, line end and confidence for a followed track."""
        cfg = self.config
        pts_x, pts_y, pts_w, pts_b = t.pts_x, t.pts_y, t.pts_w, t.pts_b
        ring_x, ring_y = t.ring_x, t.ring_y
        stop, last_b, b0, slope = t.stop, t.last_b, t.b0, t.slope
        px, py = np.array(pts_x), np.array(pts_y)
        length = px[-1] - px[0] if len(px) > 1 else 0.0

        # --- offset and angle at the look-ahead
        L = cfg.lookahead_m
        sel = np.abs(px - L) <= cfg.fit_window_m
        if sel.sum() < 4:
            sel = np.zeros(len(px), bool)
            sel[np.argsort(np.abs(px - L))[:12]] = True
        if sel.sum() >= 2 and np.ptp(px[sel]) > 1e-6:
            b_fit, a_fit = _fit_line(px[sel] - L, py[sel])
        else:
            b_fit, a_fit = slope, py[-1] + slope * (L - px[-1])
        angle = math.atan(b_fit)
        width = self._width(s, np.flatnonzero(sel), pts_y, pts_w, pts_b) * math.cos(angle)

        # --- junctions on the tracked line
        kind, jxy = self._junction(mask, s, ring_x, ring_y)

        # --- the line ends in view?
        end_xy = None
        if stop == "gap" and jxy is None:
            end_xy = (float(px[-1]), float(py[-1]))
        elif stop == "gap" and jxy is not None and jxy[0] < px[-1] - cfg.junction_radius_m - cfg.max_gap_m:
            end_xy = (float(px[-1]), float(py[-1]))

        # --- confidence
        span_bands = max(1, last_b - b0 + 1)
        coverage = len(px) / max(1, span_bands)
        length_factor = min(1.0, length / max(0.15, cfg.min_line_length_m))
        width_factor = 1.0 if cfg.line_width_min_m <= width <= cfg.line_width_max_m * 1.2 else 0.5
        confidence = float(max(0.0, min(1.0, coverage * length_factor * width_factor)))
        seen = confidence >= cfg.min_confidence and length >= cfg.min_line_length_m
        if seen:
            self._hint_y = float(py[0])
            j = min(len(px) - 1, max(1, int(np.searchsorted(px, px[0] + 0.05))))
            self._hint_slope = float((py[j] - py[0]) / (px[j] - px[0])) if px[j] > px[0] else 0.0
            self._misses = 0
        else:
            self._note_miss()
        obs = LineObservation(
            stamp_s=stamp_s,
            seen=bool(seen),
            offset_m=float(a_fit) if seen else 0.0,
            angle_rad=float(angle) if seen else 0.0,
            width_m=width if seen else 0.0,
            confidence=confidence,
            intersection=bool(seen and jxy is not None),
            intersection_distance_m=float(jxy[0]) if (seen and jxy is not None) else None,
            line_end=bool(seen and end_xy is not None),
        )
        return LineDetection(
            observation=obs,
            points=np.column_stack([px, py]),
            intersection_kind=kind if obs.intersection else None,
            intersection_xy=(float(jxy[0]), float(jxy[1])) if obs.intersection and jxy is not None else None,
            end_xy=end_xy if obs.line_end else None,
            stop_reason=stop,
        )

    def _in_glare(self, s: _Setup, band: int, y: float) -> bool:
        """True when the floor at (band, y) was clipped as a highlight."""
        if self._glare is None:
            return False
        row = s.n_rows - 1 - band * s.band_rows - s.band_rows // 2
        col = int(round((s.y_left - y) / s.res))
        if not 0 <= col < s.n_cols:
            return False
        # Near a clipped spot the tape is washed out too: look a few centimetres around.
        k = s.glare_reach
        return bool(self._glare[max(0, row - k) : row + k + 1, max(0, col - k) : col + k + 1].any())

    def _width(self, s: _Setup, idx: np.ndarray, pts_y: list[float], pts_w: list[float], pts_b: list[int]) -> float:
        """Median line width across the bands ``idx``, metres along the band.

        The thresholded run is wider than the line by the blur of its edges, so where the
        darkness is known the width is its area over its peak (a full width at half depth).
        """
        widths = []
        dark = self._darkness
        for k in idx[:: max(1, len(idx) // 8)].tolist():
            if dark is None:
                widths.append(pts_w[k])
                continue
            row = s.n_rows - 1 - pts_b[k] * s.band_rows - s.band_rows // 2
            c_mid = (s.y_left - pts_y[k]) / s.res
            half = pts_w[k] / s.res / 2.0 + 2.0
            c0, c1 = max(0, int(c_mid - half)), min(s.n_cols, int(math.ceil(c_mid + half)) + 1)
            prof = dark[row, c0:c1]
            peak = int(prof.max()) if prof.size else 0
            widths.append(float(prof.sum()) / peak * s.res if peak > 0 else pts_w[k])
        return float(np.median(widths)) if widths else 0.0

    def _note_miss(self) -> None:
        self._misses += 1
        if self._misses > 10:  # lost for a while: look straight ahead again
            self._hint_y, self._hint_slope = 0.0, 0.0

    def _lost(self, stamp_s: float) -> LineDetection:
        self._note_miss()
        return LineDetection(observation=LineObservation(stamp_s=stamp_s, seen=False), stop_reason="none")

    def _junction(
        self,
        mask: np.ndarray,
        s: _Setup,
        ring_x: list[float],
        ring_y: list[float],
    ) -> tuple[Optional[str], Optional[tuple[float, float]]]:
        """Count the arms around each tracked centre; locate and classify the first junction."""
        cfg = self.config
        cx, cy = np.array(ring_x), np.array(ring_y)
        ci = (s.x_far - cx) / s.res
        cj = (s.y_left - cy) / s.res
        ii = np.rint(ci[:, None] + s.ring_di[None, :]).astype(np.int64)
        jj = np.rint(cj[:, None] + s.ring_dj[None, :]).astype(np.int64)
        inside = (ii >= 0) & (ii < s.n_rows) & (jj >= 0) & (jj < s.n_cols)
        iic, jjc = np.clip(ii, 0, s.n_rows - 1), np.clip(jj, 0, s.n_cols - 1)
        ok = inside & s.valid[iic, jjc]
        dark = ok & (mask[iic, jjc] > 0)
        usable = ok.mean(axis=1) >= 0.9
        # close single-sample holes, drop single-sample specks, then count arcs
        filled = dark | (np.roll(dark, 1, axis=1) & np.roll(dark, -1, axis=1))
        clean = filled & (np.roll(filled, 1, axis=1) | np.roll(filled, -1, axis=1))
        arcs = (clean & ~np.roll(clean, 1, axis=1)).sum(axis=1)
        hit = usable & (arcs >= 3)
        if not hit.any():
            return None, None
        # first run of consecutive hits long enough
        run_start, run_len, first = -1, 0, None
        for k, h in enumerate(hit.tolist()):
            if h:
                if run_len == 0:
                    run_start = k
                run_len += 1
                if run_len >= cfg.junction_min_hits:
                    first = run_start
            else:
                if first is not None:
                    break
                run_len = 0
        if first is None:
            return None, None
        last = first
        while last + 1 < len(hit) and hit[last + 1]:
            last += 1
        # Every arc on the hit rings is where an arm's centreline crosses that ring.
        r = cfg.junction_radius_m
        arc_pts = []
        for k in range(first, last + 1):
            for a in _arc_centres(clean[k], s.ring_phi):
                arc_pts.append((cx[k] + r * math.cos(a), cy[k] + r * math.sin(a)))
        centre = np.array([cx[first:last + 1].mean(), cy[first:last + 1].mean()])
        arms: list[float] = []
        for _ in range(2):  # refine once from the improved centre
            found = _arms_meet(np.array(arc_pts), centre, r)
            if found is None:
                break
            new_centre, new_arms = found
            if not (cx[first] - r - 0.02 <= new_centre[0] <= cx[last] + r + 0.02):
                break  # a wild intersection (nearly parallel arms): keep the last good centre
            centre, arms = new_centre, new_arms
        if not arms:  # arm directions as seen from the first ring's centre
            arms = _arc_centres(clean[first], s.ring_phi)
        return junction_kind(arms), (float(centre[0]), float(centre[1]))

    # --- drawing -------------------------------------------------------------------------
    def draw_overlay(self, image: np.ndarray, obs: Optional[LineObservation] = None) -> np.ndarray:
        """A copy of ``image`` (BGR) with the examined floor, the tracked line, the look-ahead target and any junction drawn on it.

        Uses the last :meth:`detect` result; ``obs`` defaults to its observation.
        """
        out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        h, w = out.shape[:2]
        geom = self.geometry.scaled_to(w, h)
        det = self.last
        obs = obs if obs is not None else (det.observation if det else None)
        s = self._setup(w, h)

        def to_px(xy: np.ndarray) -> np.ndarray:
            uv = geom.ground_to_pixels(np.asarray(xy, float).reshape(-1, 2))
            return np.round(uv).astype(np.int32)

        y_lo, y_hi = -self.config.roi_half_width_m, self.config.roi_half_width_m
        x_near, x_far = float(s.band_x[0]), float(s.band_x[-1])
        roi = to_px(np.array([[x_near, y_hi], [x_far, y_hi], [x_far, y_lo], [x_near, y_lo]]))
        cv2.polylines(out, [roi], True, (255, 200, 0), 1, cv2.LINE_AA)
        if det is not None and len(det.points):
            cv2.polylines(out, [to_px(det.points)], False, (0, 220, 0), 2, cv2.LINE_AA)
        if obs is not None and obs.seen:
            tgt = to_px(np.array([[self.config.lookahead_m, obs.offset_m]]))[0]
            cv2.circle(out, (int(tgt[0]), int(tgt[1])), 5, (0, 0, 255), 2, cv2.LINE_AA)
            text = f"off {obs.offset_m * 100:+.1f} cm  ang {math.degrees(obs.angle_rad):+.1f} deg  conf {obs.confidence:.2f}"
            cv2.putText(out, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 255), 1, cv2.LINE_AA)
            if det is not None and det.intersection_xy is not None:
                j = to_px(np.array([det.intersection_xy]))[0]
                cv2.drawMarker(out, (int(j[0]), int(j[1])), (255, 0, 255), cv2.MARKER_CROSS, 16, 2)
                cv2.putText(out, f"{det.intersection_kind} at {obs.intersection_distance_m:.2f} m", (4, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 0, 255), 1, cv2.LINE_AA)
            if det is not None and det.end_xy is not None:
                e = to_px(np.array([det.end_xy]))[0]
                cv2.drawMarker(out, (int(e[0]), int(e[1])), (0, 128, 255), cv2.MARKER_TILTED_CROSS, 12, 2)
        return out


def _fit_line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares ``y = slope x + intercept``; returns (slope, intercept)."""
    xm, ym = float(x.mean()), float(y.mean())
    dx = x - xm
    sxx = float(dx @ dx)
    slope = float(dx @ (y - ym)) / sxx if sxx > 0 else 0.0
    return slope, ym - slope * xm


def _arms_meet(arc_pts: np.ndarray, centre: np.ndarray, radius_m: float) -> Optional[tuple[np.ndarray, list[float]]]:
    """Where the arms of a junction meet, from the ring arcs their centrelines crossed.

    The arc points are grouped into arms by their direction from ``centre``
    (a gap of more than 20 deg starts a new arm); a line is fitted through
    each arm's points, and the point nearest to all arm lines (least squares)
    is returned with the arms' directions from it (rad). None when the arms
    do not pin a point down (all parallel).
    """
    if len(arc_pts) < 2:
        return None
    rel = arc_pts - centre
    dist = np.hypot(rel[:, 0], rel[:, 1])
    keep = dist > 0.4 * radius_m  # directions of points close to the centre are unreliable
    pts, rel = arc_pts[keep], rel[keep]
    if len(pts) < 2:
        return None
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    order = np.argsort(ang)
    pts, ang = pts[order], ang[order]
    gaps = np.diff(np.concatenate([ang, ang[:1] + 2 * math.pi]))
    cut = int(np.argmax(gaps))  # start after the widest gap so no arm straddles the wrap
    idx = np.roll(np.arange(len(ang)), -(cut + 1))
    groups: list[list[int]] = [[int(idx[0])]]
    for prev, cur in zip(idx[:-1], idx[1:]):
        step = (ang[cur] - ang[prev]) % (2 * math.pi)
        if step > math.radians(20):
            groups.append([])
        groups[-1].append(int(cur))
    a_sum, b_sum = np.zeros((2, 2)), np.zeros(2)
    directions = []
    for g in groups:
        q = pts[g]
        qm = q.mean(axis=0)
        if len(g) >= 2 and np.ptp(q[:, 0]) + np.ptp(q[:, 1]) > 0.01:
            d = np.linalg.svd(q - qm)[2][0]
        else:
            d = (qm - centre) / max(float(np.hypot(*(qm - centre))), 1e-9)
        proj = np.eye(2) - np.outer(d, d)
        a_sum += len(g) * proj
        b_sum += len(g) * proj @ qm
        directions.append(qm)
    if np.linalg.cond(a_sum) > 1e4:
        return None
    meet = np.linalg.solve(a_sum, b_sum)
    return meet, [math.atan2(q[1] - meet[1], q[0] - meet[0]) for q in directions]


def _arc_centres(seq: np.ndarray, phi: np.ndarray) -> list[float]:
    """Centre angles (rad) of the runs of True in a circular boolean sequence sampled at ``phi``."""
    n = len(seq)
    if seq.all() or not seq.any():
        return []
    startk = int(np.argmin(seq))  # rotate so the sequence starts on a False sample
    rolled = np.roll(seq, -startk).tolist()
    out = []
    k = 0
    while k < n:
        if rolled[k]:
            j = k
            while j + 1 < n and rolled[j + 1]:
                j += 1
            mid = (k + j) / 2.0 + startk
            out.append(float(phi[0] + (mid % n) * (2 * math.pi / n)))
            k = j + 1
        else:
            k += 1
    return out
