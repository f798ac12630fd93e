"""The ego's lateral position from the video: lane markings fused with GPS.

GPS places the ego along its route well (a few metres along a 500 m drive hardly matter) but
across the road badly: a consumer receiver wanders 1-4 m, more than a lane. The lane
markings measure the other half: where in its lane the ego is (a few centimetres) and when it
changes lanes. :func:`fuse_lateral` keeps the GPS's along-track position and takes the
lateral one from the markings:

- **With a map** (an OSM road with lanes): the ego's lane index comes from GPS agreement and
  the markings (a road edge or solid line with nothing beyond on the right means the
  rightmost lane), its changes from the lane track; the ego is placed at
  ``lane boundary - distance to it`` from the road's centerline, the boundary counted from
  the carriageway's middle (the centre line of a two-way road) in measured lane widths.
- **Without a map** the road is the smoothed ego path itself, so there is nothing to place
  the ego against: its absolute position stays the GPS's. What the markings still give is
  the ego's lane (counted from the lines seen right of it), its lane changes, its offset in
  the lane and the path of the lane's middle (``lane_center_xy_m``: the ego path with the
  wander and lane changes taken out), the reference line a road built from the trajectory
  should follow.

Pure function: records in, a record out.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import gaussian_filter1d

from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import (
    EgoLateral,
    EgoTrack,
    LaneChange,
    LaneTrack,
    MarkingKind,
    Note,
    RoadResult,
)
from vid2sim.geo.lateral_config import LateralConfig
from vid2sim.geo.mapmatch import signed_offsets


def _interp_finite(t: np.ndarray, t_src: np.ndarray, v: np.ndarray, max_hold_s: float
                   ) -> np.ndarray:
    """``v`` at times ``t``: linear between finite samples, held flat up to ``max_hold_s``
    beyond the first and last; NaN inside gaps longer than ``2 * max_hold_s`` and beyond."""
    ok = np.isfinite(v)
    out = np.full(len(t), np.nan)
    if not ok.any():
        return out
    ts, vs = t_src[ok], v[ok]
    out = np.interp(t, ts, vs)
    j = np.searchsorted(ts, t)
    before = np.where(j > 0, t - ts[np.maximum(j - 1, 0)], np.inf)
    after = np.where(j < len(ts), ts[np.minimum(j, len(ts) - 1)] - t, np.inf)
    inside = (j > 0) & (j < len(ts))
    gap_ok = np.where(inside, np.minimum(before, after) <= max_hold_s, False)
    gap_ok |= (j == 0) & (after <= max_hold_s)
    gap_ok |= (j == len(ts)) & (before <= max_hold_s)
    out[~gap_ok] = np.nan
    return out


def _step_at(t: np.ndarray, t_src: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Piecewise-constant ``v`` (the last value at or before each time)."""
    j = np.clip(np.searchsorted(t_src, t, side="right") - 1, 0, len(t_src) - 1)
    return np.asarray(v)[j]


def _smooth_polyline(xy: np.ndarray, sigma_m: float, step_m: float = 0.5) -> np.ndarray:
    """Resample at ``step_m`` and Gaussian-smooth the coordinates over arc length."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    keep = np.concatenate(([True], seg > 1e-9))
    xy = xy[keep]
    if len(xy) < 3 or sigma_m <= 0:
        return xy
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))))
    s_new = np.arange(0.0, s[-1] + 1e-9, step_m)
    res = np.column_stack((np.interp(s_new, s, xy[:, 0]), np.interp(s_new, s, xy[:, 1])))
    return np.column_stack([gaussian_filter1d(res[:, k], sigma_m / step_m, mode="nearest")
                            for k in (0, 1)])


def _project_along(line: np.ndarray, xy: np.ndarray, t: np.ndarray, speed: np.ndarray,
                   chunk: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Arc length and signed offset of each ego sample on ``line``, each second's samples
    searched near where the previous second ended plus the distance driven (a route that
    passes a place twice is not confused; GPS wander does not accumulate)."""
    s_out = np.full(len(xy), np.nan)
    d_out = np.full(len(xy), np.nan)
    s_prev = t_prev = None
    for k0 in range(0, len(xy), chunk):
        sl = slice(k0, k0 + chunk)
        if s_prev is None:
            s_c, d_c = signed_offsets(line, xy[sl])
        else:
            ahead = s_prev + np.maximum(speed[sl], 0.0) * (t[sl] - t_prev)
            s_c, d_c = signed_offsets(line, xy[sl], ahead)
        s_out[sl], d_out[sl] = s_c, d_c
        last = np.flatnonzero(np.isfinite(s_c))
        if last.size:
            s_prev, t_prev = float(s_c[last[-1]]), float(t[sl][last[-1]])
    return s_out, d_out


def _frame_on_line(line: np.ndarray, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points and left normals of a polyline at arc lengths ``s_m``."""
    seg = np.diff(line, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate(([0.0], np.cumsum(length)))
    s = np.clip(s_m, 0.0, cum[-1])
    pts = np.column_stack((np.interp(s, cum, line[:, 0]), np.interp(s, cum, line[:, 1])))
    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    tangent = seg[k] / np.maximum(length[k], 1e-12)[:, None]
    return pts, np.column_stack((-tangent[:, 1], tangent[:, 0]))


def _headings(x: np.ndarray, y: np.ndarray, t: np.ndarray, speed: np.ndarray,
              fallback: np.ndarray) -> np.ndarray:
    """Direction of travel along the corrected path where the ego moves, else ``fallback``."""
    if len(t) < 2:
        return fallback.copy()
    dx, dy = np.gradient(x, t), np.gradient(y, t)
    moving = (speed > 1.0) & (np.hypot(dx, dy) > 0.5)
    return np.where(moving, np.arctan2(dy, dx), fallback)


def rightmost_evidence(track: LaneTrack) -> np.ndarray:
    """Per measured frame: the right boundary is a road edge or a solid line with no line
    beyond it, i.e. the markings say the ego is in the rightmost lane."""
    edge = np.array([k in (MarkingKind.ROAD_EDGE.value, MarkingKind.SOLID.value)
                     for k in track.right_kind], bool).reshape(-1)
    return edge & (np.asarray(track.lines_right) == 0) & np.isfinite(track.ego_offset_m)


def fuse_lateral(ego: EgoTrack, lanes: LaneTrack | None, road: RoadResult | None = None,
                 config: LateralConfig | None = None, speed_known: bool = True,
                 refilter: Callable[[LaneTrack, np.ndarray], LaneTrack] | None = None
                 ) -> EgoLateral:
    """Correct the ego's lateral position with the lane markings (see the module docstring).

    Parameters
    ----------
    ego : EgoTrack
        The smoothed GPS ego track (scenario clock, ENU).
    lanes : LaneTrack or None
        The lane markings measured while the frames streamed (re-filtered here with the
        ego's speed); None or empty leaves the ego as it is.
    road : RoadResult, optional
        The road stage's result: a map road (``source "osm"``) is what the ego is placed
        on; a trajectory road or none gives the lane facts without moving the ego.
    config : LateralConfig, optional
    speed_known : bool
        The ego's speed is measured (GPS); False for an assumed speed, which then does not
        steer the lane filter.
    refilter : callable, optional
        ``(lane track, ego speed at its frames [m/s]) -> lane track``: the lane filter run
        again with the ego's speed (the application passes
        :func:`vid2sim.detect.lanes.track.lane_track`; a stage receives it rather than
        importing another stage). None uses ``lanes`` as they are.

    Returns
    -------
    EgoLateral
    """
    cfg = config or LateralConfig()
    n = len(ego.t_s)
    nan = np.full(n, np.nan)
    unchanged = EgoLateral(ego=ego, lane=np.zeros(n, int), offset_in_lane_m=nan.copy(),
                           offset_from_centerline_m=nan.copy(), correction_m=np.zeros(n),
                           lane_width_m=nan.copy(), source="gps")
    if lanes is None or len(lanes) == 0 or n == 0:
        unchanged.notes.append(Note.warning(
            "no lane markings measured: the ego's lateral position is the GPS's"))
        return unchanged
    speed_obs = (np.interp(lanes.t_s, ego.t_s, ego.speed_mps) if speed_known
                 else np.full(len(lanes), np.nan))
    track = refilter(lanes, speed_obs) if refilter is not None else lanes
    lane_facts = _LaneFacts.on_clock(ego.t_s, track, cfg.max_hold_s)
    coverage = float(np.isfinite(track.ego_offset_m).mean())
    if coverage < cfg.min_coverage or not np.isfinite(lane_facts.offset).any():
        unchanged.notes.append(Note.warning(
            f"lane markings measured on {coverage:.0%} of the frames: too few to place the "
            "ego across the road; its lateral position is the GPS's"))
        unchanged.lanes = track
        return unchanged
    w_video = float(np.nanmedian(track.lane_width_m))
    main = None
    if road is not None and road.source == "osm" and road.roads:
        main = max(road.roads, key=lambda r: len(r.centerline))
    if main is None:
        return _without_map(ego, track, lane_facts.offset, lane_facts.width, lane_facts.lane_rel,
                            w_video, coverage, [])
    return _on_map_road(ego, track, lane_facts, main, road, w_video, coverage, cfg)


@dataclass(slots=True)
class _LaneFacts:
    """The lane track's facts at the ego's samples: the ego's offset in its lane [m], the
    lane's width [m] and the ego's lane relative to the clip's first one."""

    offset: np.ndarray
    width: np.ndarray
    lane_rel: np.ndarray

    @classmethod
    def on_clock(cls, t_s: np.ndarray, track: LaneTrack, max_hold_s: float) -> _LaneFacts:
        return cls(offset=_interp_finite(t_s, track.t_s, track.ego_offset_m, max_hold_s),
                   width=_interp_finite(t_s, track.t_s, track.lane_width_m, max_hold_s),
                   lane_rel=_step_at(t_s, track.t_s, track.lane))


@dataclass(slots=True)
class _CrossSection:
    """Where each lane lies across a map road: ``total`` lanes, ``forward`` of them in the
    ego's direction, ``width_m`` [m] per sample."""

    total: int
    forward: int
    width_m: np.ndarray

    def offsets(self, j0: int, facts: _LaneFacts) -> np.ndarray:
        """The ego's offset from the centerline [m, left] with the clip's first lane ``j0``
        (0 = the rightmost lane in its direction)."""
        j = j0 + facts.lane_rel
        w = self.width_m
        if self.total > self.forward:  # two-way: count lanes from the centre line (offset 0)
            left_boundary = -(self.forward - 1 - j) * w
        else:  # one-way: lanes centred on the centerline
            left_boundary = (j + 1 - 0.5 * self.total) * w
        return left_boundary - 0.5 * w + facts.offset


def _first_lane(ego: EgoTrack, track: LaneTrack, facts: _LaneFacts, section: _CrossSection,
                d_gps: np.ndarray, cfg: LateralConfig) -> int:
    """The clip's first lane: the one whose offsets agree best with the GPS (errors
    correlated over ``gps_correlation_s``, so the clip's mean has duration / correlation
    independent samples), where markings that say "rightmost" while the ego would not be
    there weigh like a 2-sigma GPS disagreement."""
    n = len(ego.t_s)
    valid = np.isfinite(facts.offset) & np.isfinite(d_gps)
    duration = float(ego.t_s[-1] - ego.t_s[0]) if n > 1 else 0.0
    n_eff = max(1.0, duration / cfg.gps_correlation_s)
    sigma_mean = cfg.gps_lateral_std_m / math.sqrt(n_eff)
    rightmost = rightmost_evidence(track)
    measured = np.isfinite(track.ego_offset_m)
    choices = [j for j in range(max(section.forward, 1))
               if j + int(facts.lane_rel.min()) >= 0
               and j + int(facts.lane_rel.max()) <= section.total - 1] or [0]
    costs = []
    for j0 in choices:
        resid = (float(np.mean((d_gps - section.offsets(j0, facts))[valid])) if valid.any()
                 else 0.0)
        wrong = rightmost & (j0 + track.lane > 0)
        costs.append((resid / sigma_mean) ** 2
                     + 4.0 * float(wrong.sum() / max(measured.sum(), 1)))
    return choices[int(np.argmin(costs))]


def _on_map_road(ego: EgoTrack, track: LaneTrack, facts: _LaneFacts, main, road: RoadResult,
                 w_video: float, coverage: float, cfg: LateralConfig) -> EgoLateral:
    """The ego moved across the map road to where the lane markings put it (see the module
    docstring); where the markings say nothing the GPS places it, blended over ``blend_s``."""
    line = _smooth_polyline(np.asarray(main.centerline, float), cfg.centerline_smoothing_m)
    s, d_gps = _project_along(line, np.column_stack((ego.x_m, ego.y_m)), ego.t_s,
                              ego.speed_mps)
    total = int(main.lanes)
    section = _CrossSection(total=total,
                            forward=int(road.lanes_forward) if road.lanes_forward else total,
                            width_m=np.where(np.isfinite(facts.width), facts.width, w_video))
    j0 = _first_lane(ego, track, facts, section, d_gps, cfg)
    d_video = section.offsets(j0, facts)
    lane = j0 + facts.lane_rel
    have = np.isfinite(d_video)
    weight = _blend_weight(ego.t_s, have, cfg.blend_s)
    d_gps_filled = np.where(np.isfinite(d_gps), d_gps, 0.0)
    d_new = np.where(have, d_video, d_gps_filled)
    d_new = weight * d_new + (1.0 - weight) * d_gps_filled
    pts, normal = _frame_on_line(line, s)
    x_new = pts[:, 0] + normal[:, 0] * d_new
    y_new = pts[:, 1] + normal[:, 1] * d_new
    # Samples beyond the road's ends, or far off it (another piece of a broken route), stay.
    length = float(np.hypot(*np.diff(line, axis=0).T).sum())
    on_road = (np.isfinite(d_gps) & (np.abs(d_gps) <= total * w_video + 10.0)
               & (s > 0.0) & (s < length))
    x_new = np.where(on_road, x_new, ego.x_m)
    y_new = np.where(on_road, y_new, ego.y_m)
    correction = np.where(on_road, d_new - d_gps_filled, 0.0)
    changes = [LaneChange(c.t_s, c.from_lane + j0, c.to_lane + j0) for c in track.lane_changes]
    notes = [Note.estimate(
        f"ego placed across the road from the lane markings ({coverage:.0%} of frames "
        f"measured): lane {int(np.median(lane))} of {section.forward} in its direction (0 = "
        f"rightmost), {len(changes)} lane change(s), lateral correction of the GPS "
        f"{np.sqrt(np.mean(correction ** 2)):.1f} m RMS")]
    return EgoLateral(ego=_moved(ego, x_new, y_new), lane=lane.astype(int),
                      offset_in_lane_m=facts.offset,
                      offset_from_centerline_m=np.where(on_road, d_new, np.nan),
                      correction_m=correction, lane_width_m=facts.width, lane_changes=changes,
                      lane_center_xy_m=None, source="lane markings + map", lanes=track,
                      notes=notes)


def _blend_weight(t: np.ndarray, have: np.ndarray, blend_s: float) -> np.ndarray:
    """1 where ``have``, falling linearly to 0 over ``blend_s`` away from it."""
    if not have.any():
        return np.zeros(len(t))
    th = t[have]
    j = np.clip(np.searchsorted(th, t), 1, max(len(th) - 1, 1))
    if len(th) == 1:
        dist = np.abs(t - th[0])
    else:
        dist = np.minimum(np.abs(t - th[j - 1]), np.abs(th[np.minimum(j, len(th) - 1)] - t))
    return np.clip(1.0 - dist / max(blend_s, 1e-9), 0.0, 1.0)


def _moved(ego: EgoTrack, x: np.ndarray, y: np.ndarray) -> EgoTrack:
    """The ego track at new positions: headings from the path, lat/lon recomputed."""
    heading = _headings(x, y, ego.t_s, ego.speed_mps, ego.heading_rad)
    lat, lon, _ = EnuFrame(ego.origin).to_geodetic(np.column_stack((x, y)))
    return replace(ego, x_m=x, y_m=y, heading_rad=heading, lat_deg=np.asarray(lat, float),
                   lon_deg=np.asarray(lon, float))


def _without_map(ego: EgoTrack, track: LaneTrack, offset: np.ndarray, width: np.ndarray,
                 lane_rel: np.ndarray, w_video: float, coverage: float, notes: list[str]
                 ) -> EgoLateral:
    """A road derived from the trajectory: the ego stays where GPS put it; the lane facts
    and the path of the lane's middle come from the markings."""
    n = len(ego.t_s)
    # Lanes to the right of the first lane: the lines seen right of the ego before a road
    # edge or solid line (each further line bounds one more lane).
    ok = np.isfinite(track.ego_offset_m)
    start = ok & (track.lane == 0)
    evidence = rightmost_evidence(track)[start]
    if not start.any() or evidence.mean() >= 0.5:
        j0 = 0
    else:
        j0 = int(np.median(np.asarray(track.lines_right)[start]))
    lane = (j0 + lane_rel).astype(int)
    w = np.where(np.isfinite(width), width, w_video)
    # The middle of the first lane: the ego path moved by its offset and lane changes.
    shift = np.where(np.isfinite(offset), offset + lane_rel * w, np.nan)
    c, s_ = np.cos(ego.heading_rad), np.sin(ego.heading_rad)
    shift_f = np.where(np.isfinite(shift), shift, 0.0)
    centre = np.column_stack((ego.x_m + s_ * shift_f, ego.y_m - c * shift_f))
    centre[~np.isfinite(shift)] = np.nan
    changes = [LaneChange(ch.t_s, ch.from_lane + j0, ch.to_lane + j0)
               for ch in track.lane_changes]
    notes.append(Note.estimate(
        f"lane markings measured on {coverage:.0%} of the frames: ego in lane {j0} counted "
        f"from the right at the start, {len(changes)} lane change(s), lane width "
        f"{w_video:.2f} m; no map to place the ego against, so its path is kept as it was"))
    return EgoLateral(ego=ego, lane=lane, offset_in_lane_m=offset,
                      offset_from_centerline_m=np.full(n, np.nan), correction_m=np.zeros(n),
                      lane_width_m=width, lane_changes=changes, lane_center_xy_m=centre,
                      source="lane markings (no map)", lanes=track, notes=notes)
