"""Lane markings as a measurement: the ego lane's boundaries in the ground plane, per frame.

Method (classical, OpenCV + numpy; no learned model):

1. **Bird's-eye view.** The road band of a downscaled grey frame is resampled onto a ground
   grid in the vehicle frame (x forward, y left; :class:`BevGrid`) with one precomputed
   ``cv2.remap`` (the inverse perspective mapping of the camera's pinhole model onto the
   road plane z = 0).
2. **Ridges.** A painted line is a narrow stripe brighter than the asphalt on *both* sides;
   the response is the smaller of the two centre-minus-side contrasts (a step edge such as a
   shadow's border gives one side only), divided by the local brightness so that markings in
   shade count as much as in sun. Lateral local maxima above a threshold are marking points.
3. **Lines.** A Hough vote over (offset, heading) of the near points finds straight
   candidates near the strongest line's direction (lines on a road are parallel); each is
   refined on the row centroids of its points, and those that still run parallel are fitted
   together: one clothoid shape ``c1 x + c2 x^2 / 2 + c3 x^3 / 6`` for all, each its own
   offset ``c0`` (:func:`~vid2sim.detect.lanes.geometry.fit_parallel_lines`), so a dashed line
   seen as two dashes borrows the solid line's direction.
4. **Kind.** Along the fitted line, the rows where paint was found give its pattern: one long
   run is solid, several short runs with gaps are dashed. Separately, on each side the first
   stretch of rough surface (gravel, grass, a track bed, a parked car) outwards from the
   camera is the road's edge (a kerb without paint is found this way); lines beyond it are
   not on the road.
5. **Ego lane.** The nearest line on each side is the lane's boundary when the pair makes a
   plausible lane; the others are the further lines.

Why the offsets hold up when the camera's pitch is off: a horizon error of ``d`` pixels
maps a straight ground line ``y = c0 + c1 x`` to ``y' = c0 + (c1 + c0 d / (h f)) x'`` in the
warped view (``h`` camera height, ``f`` focal length): its offset at x = 0 is unchanged;
only its heading is biased, by opposite amounts for lines on opposite sides.

The pure geometry lives in :mod:`vid2sim.detect.lanes.geometry`; :class:`LaneMarkingDetector`
holds the precomputed warp and measures one frame (about 2.5 ms at 1242x375 on one core).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import cv2
import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.records import LaneBoundary, LaneObservation, MarkingKind
from vid2sim.detect.lanes.geometry import (
    BevGrid,
    fit_lines,
    fit_parallel_lines,
    ground_to_pixel_maps,
    hough_lines,
    pattern_kind,
    pick_ego_lane,
    ridge_response,
    weighted_median,
)


@dataclass(frozen=True, slots=True)
class LaneMarkingConfig:
    """Tuning of the per-frame lane-marking measurement (sources in the comments).

    Distances in metres in the vehicle frame, contrasts in grey levels (0-255).
    """

    #: half width of the ground grid: the ego lane and one or two lanes beside it (lanes are
    #: 2.75-3.75 m, RASt 06 / FHWA)
    half_width_m: float = 10.0
    #: nearest and farthest ground distance looked at; beyond ~35 m a 0.12 m line is under
    #: 3 px wide at KITTI's focal length and the flat-road assumption weakens
    near_m: float = 3.0
    far_m: float = 35.0
    #: grid resolution: lateral 5 cm (half a marking's width), longitudinal 25 cm
    lateral_step_m: float = 0.05
    longitudinal_step_m: float = 0.25
    #: frames are downscaled to at most this width first (cost; the grid's resolution is
    #: coarser than a pixel beyond ~10 m anyway)
    max_width_px: int = 640
    #: distance from the line's centre to where the asphalt beside it is sampled: half a broad
    #: marking (0.25-0.30 m edge lines, VwV-StVO Z 295) plus a margin
    side_m: float = 0.25
    #: a marking is at least this much brighter than the asphalt on both sides, absolute and
    #: relative to the local brightness (painted lines are 30-100 % brighter than asphalt; 12 %
    #: keeps worn paint and shade; measured on KITTI raw 0001, benchmarks/bench_lanes.py)
    min_contrast: float = 6.0
    min_relative_contrast: float = 0.12
    #: Hough range of headings (a lane change is 2-6 deg; 12 deg leaves room for curves)
    max_heading_rad: float = 0.21
    heading_step_rad: float = 0.0105
    offset_bin_m: float = 0.1
    #: lines on a road are parallel: candidates within this heading of the strongest line
    parallel_tolerance_rad: float = 0.04
    #: a candidate has at least this share of the strongest line's votes, and at most this
    #: many candidates are fitted (a road shows at most 6-8 lines in 20 m of width)
    min_relative_votes: float = 0.15
    max_candidates: int = 10
    #: a fitted line's points scatter less than this about it (a marking is 0.1-0.3 m wide;
    #: texture and shadows scatter over the whole gathering corridor)
    max_scatter_m: float = 0.1
    #: candidate lines closer than this merge (a double line is one boundary)
    min_separation_m: float = 0.5
    #: a line needs paint on at least this many metres of its length
    min_seen_m: float = 2.0
    #: half width of the corridor around a candidate from which its points are taken
    gather_m: float = 0.35
    refine_m: float = 0.2
    #: prior one-sigma of the curvature (ridge regression): 1/100 m is a tight urban bend
    curvature_prior_inv_m: float = 0.01
    #: prior one-sigma of the curvature's rate of change (a clothoid entering a 75 m bend
    #: over 30 m changes curvature by 4e-4 1/m per metre)
    curvature_rate_prior_inv_m2: float = 5e-4
    #: rows nearer than this count fully in the joint fit, farther ones by (this / x)^2
    near_weight_m: float = 10.0
    #: the Hough vote uses marking points nearer than this
    hough_far_m: float = 20.0
    #: prior one-sigma of the heading bias per metre of offset that a pitch error causes in
    #: the warped view: 0.5 deg of pitch at 1.5 m camera height (see fit_parallel_lines)
    pitch_bias_prior_inv_m: float = 0.006
    #: a lane is 2.2-4.5 m between line centres (narrowest urban lanes 2.25 m, RASt 06;
    #: the widest, 3.75 m motorway lanes, with a broad edge line and a margin)
    lane_width_range_m: tuple[float, float] = (2.2, 4.5)
    #: lines below this confidence are not taken as lines (a faint 3 m streak scores ~0.3)
    min_confidence: float = 0.3
    #: the ego lane's boundaries lie within this distance of the camera
    max_boundary_offset_m: float = 4.0
    #: kind thresholds: a solid line is painted over this share of where it is visible; a
    #: dashed line has at least two dashes with gaps of at least ``min_gap_m`` (German town
    #: dashes 3 m / gaps 6 m, Finnish 3 / 9, US 3 / 9: gaps are 1.5-4x the dash)
    solid_coverage: float = 0.75
    min_gap_m: float = 1.5
    #: the surface is "not road" where its roughness exceeds that under the ego's path by
    #: this factor (gravel and track beds are 3-10x rougher than asphalt in the warped view)
    edge_texture_ratio: float = 2.5
    #: texture is compared this near only (farther, one pixel covers several grid cells)
    texture_far_m: float = 15.0
    #: road edges are searched from this far beside the camera outwards (inside it lies the
    #: ego's own lane); rough over most of ``edge_min_run_m`` (a painted line's own edges
    #: are rough over under 0.6 m); seen on this many rows (2 m) and this share of the near
    #: rows, with inliers within this distance of the fitted edge
    edge_search_from_m: float = 0.5
    edge_min_run_m: float = 0.8
    edge_min_rows: int = 8
    edge_min_share: float = 0.4
    edge_inlier_m: float = 0.25
    #: a line whose points scatter about the road's joint shape by more than this (RMS) is
    #: not a road line (a shadow's border, a crack, a car's edge); paint scatters 3-8 cm
    shape_tolerance_m: float = 0.15


# --------------------------------------------------------------------------- the detector


class LaneMarkingDetector:
    """Measures the lane markings of single frames (see the module docstring).

    Parameters
    ----------
    camera : Camera
        The camera at the video's frame size (other frame sizes are scaled to it).
    config : LaneMarkingConfig, optional
    """

    def __init__(self, camera: Camera, config: LaneMarkingConfig | None = None):
        self.camera = camera
        self.config = config or LaneMarkingConfig()
        cfg = self.config
        self.grid = BevGrid.make(cfg.half_width_m, cfg.near_m, cfg.far_m, cfg.lateral_step_m,
                                 cfg.longitudinal_step_m)
        self._size: tuple[int, int] | None = None
        self._side_px = max(2, round(self.config.side_m / self.config.lateral_step_m))
        # Hough lines are parametrised at the middle of the well-resolved near range.
        self._x_ref = 0.5 * (self.config.near_m + min(self.config.far_m, 20.0))

    # ----------------------------------------------------------------- warp

    def _prepare(self, width: int, height: int) -> None:
        """Precompute the warp for frames of ``width`` x ``height`` pixels."""
        cam = self.camera
        if (cam.image_width, cam.image_height) != (width, height):
            cam = cam.scaled_to(width, height)
        map_u, map_v = ground_to_pixel_maps(cam, self.grid)
        inside = (np.isfinite(map_u) & np.isfinite(map_v) & (map_u >= 0) & (map_u <= width - 1)
                  & (map_v >= 0) & (map_v <= height - 1))
        # An integer factor: OpenCV's area averaging is several times slower for other ratios.
        scale = 1.0 / max(1, math.ceil(width / self.config.max_width_px))
        rows = map_v[inside]
        top = int(max(0, math.floor(rows.min()) - 2)) if rows.size else 0
        self._scale = scale
        self._top = top
        # A downscaled pixel i averages full pixels k i .. k i + k - 1: its centre is
        # (k - 1) / 2 full pixels past k i.
        half = 0.5 * (1.0 / scale - 1.0)
        map_u = np.where(inside, (map_u - half) * scale, -10.0)
        map_v = np.where(inside, (map_v - top - half) * scale, -10.0)
        self._maps = cv2.convertMaps(map_u.astype(np.float32), map_v.astype(np.float32),
                                     cv2.CV_16SC2)
        # Pixels whose ridge filter reaches outside the image are not measured.
        k = self._side_px + 3
        self._valid = cv2.erode(inside.astype(np.uint8), np.ones((3, 2 * k + 1), np.uint8)
                                ).astype(bool)
        # Rows where texture can be told (see ``texture_far_m``) with any valid pixel.
        self._texture_rows = np.flatnonzero((self.grid.x_m <= self.config.texture_far_m)
                                            & self._valid.any(axis=1))
        self._size = (width, height)

    def warp(self, image_bgr: np.ndarray) -> np.ndarray:
        """The frame's bird's-eye view (grey, uint8) on :attr:`grid`."""
        h, w = image_bgr.shape[:2]
        if self._size != (w, h):
            self._prepare(w, h)
        band = image_bgr[self._top:]
        if self._scale < 1.0:
            band = cv2.resize(band, None, fx=self._scale, fy=self._scale,
                              interpolation=cv2.INTER_AREA)
        grey = cv2.cvtColor(band, cv2.COLOR_BGR2GRAY) if band.ndim == 3 else band
        return cv2.remap(grey, self._maps[0], self._maps[1], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    # ----------------------------------------------------------------- one frame

    def measure(self, image_bgr: np.ndarray, frame: int = 0, t_s: float = 0.0
                ) -> LaneObservation:
        """The lane markings of one frame."""
        t0 = time.perf_counter()
        lines = self.find_lines(self.warp(image_bgr))
        left, right, further_left, further_right = pick_ego_lane(
            lines, width_range_m=self.config.lane_width_range_m,
            max_offset_m=self.config.max_boundary_offset_m,
            min_confidence=self.config.min_confidence)
        width = offset = float("nan")
        if left is not None and right is not None:
            width = left.offset_m - right.offset_m
            offset = -0.5 * (left.offset_m + right.offset_m)
        return LaneObservation(frame=int(frame), t_s=float(t_s), left=left, right=right,
                               lane_width_m=width, ego_offset_m=offset,
                               lines_left=further_left, lines_right=further_right,
                               cost_ms=1e3 * (time.perf_counter() - t0))

    def find_lines(self, bev: np.ndarray) -> list[LaneBoundary]:
        """All lines of a bird's-eye view (painted lines and the road's edges), by offset."""
        bevf = bev.astype(np.float32)
        texture = self._texture(bevf)
        lines, shape = self._painted_lines(bevf, texture)
        cfg = self.config
        for side in (1.0, -1.0):
            edge = self._road_edge(texture, side, shape)
            if edge is None:
                continue
            # Paint beyond the road's edge is not on the road (tram rails, parking bays
            # behind the kerb, a car's shine); a ridge on the edge itself is the kerb.
            keep = []
            on_edge = None
            for ln in lines:
                d = side * (ln.offset_m - edge.offset_m)
                if abs(d) <= cfg.min_separation_m:
                    on_edge = ln if on_edge is None or ln.confidence > on_edge.confidence \
                        else on_edge
                elif d < 0 or side * ln.offset_m <= 0:
                    keep.append(ln)
            if on_edge is not None:
                edge = replace(on_edge, kind=MarkingKind.ROAD_EDGE.value)
            lines = keep + [edge]
        return sorted(lines, key=lambda ln: ln.offset_m)

    # ----------------------------------------------------------------- painted lines

    def _painted_lines(self, bevf: np.ndarray, texture: np.ndarray
                       ) -> tuple[list[LaneBoundary], tuple[float, float] | None]:
        """Painted lines (Hough + fit), and the common (heading at x = 0, curvature) of the
        road's lines, None when no line was found."""
        points = self._ridge_points(bevf)
        if points is None:
            return [], None
        rows, x, y, w = points
        offsets, headings = self._hough_candidates(x, y, w)
        fitted, ys, ws = self._refine(rows, x, y, w, offsets, headings, self._x_ref)
        if not fitted:
            return [], None
        # The road's direction: the confidence-weighted median heading of the lines at
        # x_ref (where it is best measured); lines not parallel to it are not road lines.
        cfg, x_ref = self.config, self._x_ref
        conf = np.array([ln.confidence * ln.seen_m for ln in fitted])
        h_ref = np.array([ln.heading_rad + ln.curvature_inv_m * x_ref for ln in fitted])
        h0 = weighted_median(h_ref, conf)
        keep = np.flatnonzero(np.abs(h_ref - h0) <= cfg.parallel_tolerance_rad)
        if keep.size == 0:
            return [], None
        keep, coef, std = self._joint_fit(fitted, ys, ws, keep)
        return (self._fitted_lines(fitted, keep, coef, std),
                (float(np.median(coef[:, 1])), float(coef[0, 2])))

    def _ridge_points(self, bevf: np.ndarray):
        """One point per marking and bird's-eye row: lateral maxima of the ridge response
        above the relative and absolute contrast thresholds, as ``(rows, x [m], y [m],
        weight)``; None with fewer than 4."""
        cfg, grid = self.config, self.grid
        ridge = ridge_response(bevf, self._side_px)
        # Absolute contrast too: in near-black shade 12 % of almost nothing is noise.
        strong = (ridge >= cfg.min_relative_contrast) & self._valid
        strong &= ridge * np.maximum(cv2.blur(bevf, (5, 3)), 20.0) >= cfg.min_contrast
        peak = np.zeros_like(strong)
        peak[:, 1:-1] = (ridge[:, 1:-1] >= ridge[:, :-2]) & (ridge[:, 1:-1] > ridge[:, 2:])
        rows, cols = np.nonzero(strong & peak)
        if rows.size < 4:
            return None
        w = np.minimum(ridge[rows, cols] / cfg.min_relative_contrast, 3.0)
        return rows, grid.x_m[rows], grid.y_m[cols], w

    def _hough_candidates(self, x: np.ndarray, y: np.ndarray, w: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
        """Candidate lines (offset at x_ref [m], heading [rad]) from straight-line votes of
        the near points, where a bend is still nearly straight. Lines on a road are
        parallel: the strongest line gives the heading of all, candidates are sought near
        it, each needing votes worth ``min_seen_m`` of paint at twice the threshold
        contrast and ``min_separation_m`` from a stronger one."""
        cfg = self.config
        near_pts = x <= cfg.hough_far_m
        acc, headings, offsets = hough_lines(
            x[near_pts], y[near_pts], w[near_pts], x_ref_m=self._x_ref,
            max_heading_rad=cfg.max_heading_rad, heading_step_rad=cfg.heading_step_rad,
            half_width_m=cfg.half_width_m, offset_bin_m=cfg.offset_bin_m)
        acc = cv2.blur(acc.astype(np.float32), (3, 3))
        h_top = int(np.unravel_index(np.argmax(acc), acc.shape)[0])
        band = max(1, round(cfg.parallel_tolerance_rad / cfg.heading_step_rad))
        sub = acc[max(0, h_top - band):h_top + band + 1]
        best = sub.max(axis=0)
        best_heading = headings[max(0, h_top - band) + sub.argmax(axis=0)]
        min_votes = max(2.0 * cfg.min_seen_m / cfg.longitudinal_step_m / 3.0,
                        cfg.min_relative_votes * float(best.max()))
        sep = round(cfg.min_separation_m / cfg.offset_bin_m)
        candidates: list[int] = []
        for j in np.argsort(-best):
            if best[j] < min_votes or len(candidates) >= cfg.max_candidates:
                break
            if all(abs(j - k) > sep for k in candidates):
                candidates.append(int(j))
        return offsets[candidates], best_heading[candidates]

    def _joint_fit(self, fitted: list[LaneBoundary], ys: np.ndarray, ws: np.ndarray,
                   keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All parallel lines fitted together (one shape), near rows weighted up: a grid
        row's lateral error grows with distance (one pixel covers x / f metres). A line
        whose points stray from the joint shape is not a road line (a shadow's border, a
        crack, a car's edge): it is dropped and the rest fitted again (at most 3 times).
        Returns the lines kept, their coefficients and offset spreads."""
        cfg, grid = self.config, self.grid
        near = np.minimum(1.0, (cfg.near_weight_m / grid.x_m) ** 2)
        for attempt in range(3):
            guess = np.array([fitted[i].offset_m for i in keep])
            coef, std = fit_parallel_lines(
                grid.x_m, ys[keep], ws[keep] * near[None, :], guess,
                curvature_prior_inv_m=cfg.curvature_prior_inv_m,
                curvature_rate_prior_inv_m2=cfg.curvature_rate_prior_inv_m2,
                pitch_bias_prior_inv_m=cfg.pitch_bias_prior_inv_m)
            xx = grid.x_m[None, :]
            model = (coef[:, :1] + coef[:, 1:2] * xx + 0.5 * coef[:, 2:3] * xx ** 2
                     + coef[:, 3:4] * xx ** 3 / 6.0)
            wk = ws[keep]
            rms = np.sqrt((wk * (ys[keep] - model) ** 2).sum(axis=1)
                          / np.maximum(wk.sum(axis=1), 1e-12))
            good = rms <= cfg.shape_tolerance_m
            if good.all() or not good.any() or attempt == 2:
                break
            keep = keep[good]
        return keep, coef, std

    def _fitted_lines(self, fitted: list[LaneBoundary], keep: np.ndarray, coef: np.ndarray,
                      std: np.ndarray) -> list[LaneBoundary]:
        """The kept lines with the joint fit's shape, most confident first; of two
        candidates that met on one marking the better one."""
        keep_coef = dict(zip(keep.tolist(), coef, strict=True))
        keep_std = dict(zip(keep.tolist(), std, strict=True))
        lines: list[LaneBoundary] = []
        for i in sorted(keep.tolist(), key=lambda i: -fitted[i].confidence):
            c, sd = keep_coef[i], keep_std[i]
            line = replace(fitted[i], offset_m=float(c[0]), heading_rad=float(c[1]),
                           curvature_inv_m=float(c[2]), curvature_rate_inv_m2=float(c[3]),
                           offset_std_m=float(max(sd, fitted[i].offset_std_m)))
            if all(abs(line.offset_m - o.offset_m) >= self.config.min_separation_m
                   for o in lines):
                lines.append(line)
        return lines

    def _refine(self, rows: np.ndarray, x: np.ndarray, y: np.ndarray, w: np.ndarray,
                a_ref: np.ndarray, heading: np.ndarray, x_ref: float
                ) -> tuple[list[LaneBoundary], np.ndarray, np.ndarray]:
        """Fit each Hough candidate (offset ``a_ref`` at ``x_ref``, heading) to the points
        nearest to it, all candidates at once; drop the ones that do not look like a line.

        Returns the lines and, per line, the row centroids [m] and their weights (per grid
        row; weight 0 where the line has no point)."""
        cfg, grid = self.config, self.grid
        n_rows, k = len(grid.x_m), len(a_ref)
        if k == 0:
            return [], np.zeros((0, n_rows)), np.zeros((0, n_rows))
        pred = a_ref[:, None] + heading[:, None] * (x[None, :] - x_ref)
        for it in range(3):
            dist = np.abs(y[None, :] - pred)
            if it == 0:
                # First pass: each point to its nearest candidate, so that two candidates
                # on one marking do not both start from it.
                owner = dist.argmin(axis=0)
                pt = np.flatnonzero(dist[owner, np.arange(len(x))] <= cfg.gather_m)
                line = owner[pt]
            else:
                line, pt = np.nonzero(dist <= cfg.refine_m)
            # One weighted centroid per line and grid row: a marking several samples wide
            # counts once.
            idx = line * n_rows + rows[pt]
            sw = np.bincount(idx, weights=w[pt], minlength=k * n_rows).reshape(k, n_rows)
            sy = np.bincount(idx, weights=(w * y)[pt], minlength=k * n_rows).reshape(k, n_rows)
            ys = sy / np.maximum(sw, 1e-12)
            ws = np.minimum(sw, 3.0)
            coef, cov = fit_lines(grid.x_m, ys, ws,
                                  curvature_prior_inv_m=cfg.curvature_prior_inv_m)
            pred = (coef[:, :1] + coef[:, 1:2] * x[None, :]
                    + 0.5 * coef[:, 2:3] * (x * x)[None, :])
        fit_rows = (coef[:, :1] + coef[:, 1:2] * grid.x_m[None, :]
                    + 0.5 * coef[:, 2:3] * (grid.x_m ** 2)[None, :])
        hit = sw > 0
        scatter = np.sqrt((ws * (ys - fit_rows) ** 2).sum(axis=1) / np.maximum(ws.sum(axis=1),
                                                                            1e-12))
        seen = hit.sum(axis=1) * cfg.longitudinal_step_m
        cols = np.rint(grid.column_of(fit_rows)).astype(int)
        out: list[LaneBoundary] = []
        kept: list[int] = []
        for i in range(k):
            if seen[i] < cfg.min_seen_m or scatter[i] > cfg.max_scatter_m:
                continue
            # Where the line lies inside the measured part of the view, and where paint is.
            rows_vis = np.flatnonzero((cols[i] >= 0) & (cols[i] < len(grid.y_m)))
            rows_vis = rows_vis[self._valid[rows_vis, cols[i, rows_vis]]]
            if rows_vis.size == 0:
                continue
            kind = pattern_kind(hit[i, rows_vis], cfg.longitudinal_step_m,
                                solid_coverage=cfg.solid_coverage, min_gap_m=cfg.min_gap_m,
                                min_seen_m=cfg.min_seen_m)
            # Confidence: paint seen (10 m = full) and the fit's scatter (5 cm is good).
            confidence = min(1.0, seen[i] / 10.0) * math.exp(-(scatter[i] / 0.08) ** 2)
            std = math.sqrt(max(cov[i, 0, 0], 0.0)) * max(1.0, scatter[i] / 0.05)
            xs = grid.x_m[hit[i]]
            line = LaneBoundary(offset_m=float(coef[i, 0]), heading_rad=float(coef[i, 1]),
                                curvature_inv_m=float(coef[i, 2]), kind=kind.value,
                                confidence=round(float(confidence), 4), offset_std_m=float(std),
                                x_near_m=float(xs.min()), x_far_m=float(xs.max()),
                                seen_m=float(seen[i]))
            if all(abs(line.offset_m - o.offset_m) >= cfg.min_separation_m for o in out):
                out.append(line)
                kept.append(i)
        return out, ys[kept], ws[kept]

    # ----------------------------------------------------------------- road edges

    def _texture(self, bevf: np.ndarray) -> np.ndarray:
        """Local roughness of the surface: mean absolute high-pass over 0.25 x 1.25 m."""
        hp = np.abs(bevf - cv2.blur(bevf, (5, 3)))
        return cv2.blur(hp, (5, 5))

    def _road_edge(self, texture: np.ndarray, side: float,
                   shape: tuple[float, float] | None) -> LaneBoundary | None:
        """Where the smooth road surface ends on one side (+1 left, -1 right): per near row
        the first rough run outwards from the camera, fitted with the road's shape."""
        cfg, grid = self.config, self.grid
        rows = self._texture_rows
        if rows.size < 8:
            return None
        tex = texture[rows]
        valid = self._valid[rows]
        centre = round(float(grid.column_of(0.0)))
        # The road's own roughness: the surface under the ego's path.
        half = round(1.0 / cfg.lateral_step_m)
        road = tex[:, centre - half:centre + half + 1][valid[:, centre - half:centre + half + 1]]
        if road.size < 20:
            return None
        rough = (tex > cfg.edge_texture_ratio * max(float(np.median(road)), 1.0)) & valid
        start = round(cfg.edge_search_from_m / cfg.lateral_step_m)
        if side > 0:  # columns towards smaller index are further left
            seg, vseg = rough[:, :centre - start][:, ::-1], valid[:, :centre - start][:, ::-1]
        else:
            seg, vseg = rough[:, centre + start:], valid[:, centre + start:]
        # Rough over most of ``edge_min_run_m``: beyond a painted line's own edges (its
        # roughness spans under 0.6 m) and any speck.
        n_run = max(2, round(cfg.edge_min_run_m / cfg.lateral_step_m))
        if seg.shape[1] <= n_run:
            return None
        cs = np.concatenate((np.zeros((seg.shape[0], 1)), np.cumsum(seg, axis=1)), axis=1)
        run = (cs[:, n_run:] - cs[:, :-n_run]) >= 0.8 * n_run
        run &= seg[:, :run.shape[1]]
        has = run.any(axis=1)
        first = run.argmax(axis=1)
        # Rows whose search starts outside the image, or that never saw smooth road before
        # the rough part, say nothing.
        ok = has & vseg[:, 0] & (first > 0)
        if ok.sum() < cfg.edge_min_rows:
            return None
        x = grid.x_m[rows[ok]]
        # The roughness is averaged over 5 columns, so it rises 2 columns before the edge.
        y = side * (cfg.edge_search_from_m + (first[ok] + 2) * cfg.lateral_step_m)
        if shape is not None:
            c1, c2 = shape
            o = y - (c1 * x + 0.5 * c2 * x * x)
        else:
            c1 = c2 = 0.0
            o = y
        c0 = float(np.median(o))
        inl = np.abs(o - c0) <= cfg.edge_inlier_m
        if inl.sum() < max(cfg.edge_min_rows, cfg.edge_min_share * rows.size):
            return None
        c0 = float(np.mean(o[inl]))
        scatter = float(np.std(o[inl]))
        share = float(inl.sum() / rows.size)
        return LaneBoundary(offset_m=c0, heading_rad=float(c1), curvature_inv_m=float(c2),
                            kind=MarkingKind.ROAD_EDGE.value,
                            confidence=round(min(1.0, share) * math.exp(-(scatter / 0.15) ** 2),
                                             4),
                            offset_std_m=scatter / math.sqrt(inl.sum()),
                            x_near_m=float(x[inl].min()), x_far_m=float(x[inl].max()),
                            seen_m=float(inl.sum() * cfg.longitudinal_step_m))


