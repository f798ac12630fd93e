"""Ego trajectory from a GPS trace: outlier rejection, Kalman/RTS smoothing, resampling.

Pipeline of :func:`smooth_ego` (all in the local ENU frame, metres and seconds):

1. time alignment: scenario time ``t_s`` = seconds from the video's first frame;
2. gross outliers: the longest chain of fixes in which every step is physically possible
   (speed gating against ``v_max``) is kept, so a wild first fix or a burst cannot capture it;
3. position noise: estimated from the scatter of each fix about the line through its
   neighbours (the white part of GPS error, which is what corrupts speed), or the reported
   accuracy scaled to that estimate;
4. a constant-acceleration Kalman filter + Rauch-Tung-Striebel smoother fusing positions and,
   where reported, speed and course; fixes far from the smoothed track (jump gating) are
   dropped and the smoother re-run;
5. stops: periods whose smoothed speed is within noise of 0 and whose fixes show no net motion
   (or whose reported Doppler speed is ~0) get zero-velocity updates, then exactly speed 0,
   a fixed position and the heading held from before the stop;
6. uniform resampling at ``rate_hz`` (cubic Hermite on smoothed position and velocity), heading
   from the smoothed velocity (counter-clockwise from east).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.base.defaults import EGO_RATE_HZ
from vid2sim.base.errors import ImpossibleValueError, InconsistentInputError
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import EgoTrack, GpsTrace, Origin, TraceStats
from vid2sim.geo._gps_kalman import hermite, smooth
from vid2sim.geo.stops import (
    doppler_stops,
    held_heading,
    median3,
    position_stops,
    spans,
    stop_headings,
)
from vid2sim.geo.trace_params import TraceParams

__all__ = ["TraceParams", "format_summary", "smooth_ego", "video_t0_utc"]


# --------------------------------------------------------------------------- public API


def video_t0_utc(trace: GpsTrace, gps_offset_s: float | None = None) -> tuple[float, str]:
    """The UTC time [s] of video time 0, and how it was found: the one rule every stage
    puts the fixes on the video clock with.

    ``gps_offset_s`` is the video time of the earliest fix; without it the file's own clock
    (``trace.video_start_utc_s``) holds; without either the earliest fix is at t = 0.
    """
    first = min(f.t_utc_s for f in trace.fixes) if trace.fixes else 0.0
    if gps_offset_s is not None:
        return first - gps_offset_s, f"--gps-offset: first fix at video time {gps_offset_s:+.3f} s"
    if trace.video_start_utc_s is not None:
        t0 = trace.video_start_utc_s
        return t0, f"file clock ({trace.format}): first fix at video time {first - t0:+.3f} s"
    return first, "no video clock in the file: first fix = first frame (use --gps-offset to shift)"


def smooth_ego(trace: GpsTrace, rate_hz: float = EGO_RATE_HZ, gps_offset_s: float | None = None,
               origin: Origin | None = None,
               params: TraceParams | None = None) -> tuple[EgoTrack, TraceStats]:
    """Turn GPS fixes into a smooth, uniformly sampled ego trajectory in ENU.

    Parameters
    ----------
    trace
        Fixes from :func:`vid2sim.geo.readers.read_gps`.
    rate_hz
        Output sample rate [Hz]; samples fall on multiples of ``1 / rate_hz`` of the scenario
        clock inside the span of the fixes.
    gps_offset_s
        Video time of the first fix [s]; overrides the file's own clock
        (``trace.video_start_utc_s``). Without either, the first fix is at t 0.
    origin
        ENU origin; default the first accepted fix (its altitude, or 0 m).
    params
        Tuning; default :class:`TraceParams`.

    Returns
    -------
    (EgoTrack, TraceStats)
        The trajectory (``t_s`` [s], ``x_m``/``y_m`` [m], ``heading_rad`` CCW from east,
        ``speed_mps``, lat/lon [deg]) and a summary of what was done.

    Raises
    ------
    InputError
        Fewer than two usable fixes, a non-positive rate.
    """
    p = params or TraceParams()
    path = trace.path
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise ImpossibleValueError(path, f"output rate {rate_hz} Hz must be > 0")
    fx = _fix_arrays(trace)
    warnings = list(trace.warnings)

    # ---- 1. time alignment
    t0_utc, alignment = video_t0_utc(trace, gps_offset_s)
    if gps_offset_s is None and trace.video_start_utc_s is not None \
            and not (fx.t_utc[0] - 3600 <= t0_utc <= fx.t_utc[-1] + 3600):
        warnings.append("the file's video start is more than an hour outside the fixes; "
                        "check the clock or pass --gps-offset")
    t = fx.t_utc - t0_utc
    too_fast = fx.spd > p.v_max_mps
    if np.any(too_fast):
        warnings.append(f"ignored {int(too_fast.sum())} reported speeds above {p.v_max_mps} m/s")
        fx.spd[too_fast] = np.nan

    # ---- 2. gross outliers (speed gating), then the ENU frame at the origin
    keep = _gross_outliers(t, fx, p, path)
    if origin is None:
        i0 = int(np.flatnonzero(keep)[0])
        origin = Origin(float(fx.lat[i0]), float(fx.lon[i0]),
                        0.0 if np.isnan(fx.alt[i0]) else float(fx.alt[i0]))
    frame = EnuFrame(origin)
    enu = frame.to_enu(fx.lat, fx.lon, np.where(np.isnan(fx.alt), origin.alt, fx.alt))

    # ---- 3. position noise; 4. smoothing with jump gating; 5. stops
    noise_m = p.noise_m or _noise_estimate(t, enu[:, :2], keep, p.min_noise_m)
    meas = _measurements(t, enu[:, :2], fx, noise_m, keep, p)
    used, segments = _reject_jumps(meas, keep, p, path)
    xs, stop_spans = _smooth_with_stops(meas, used, segments, p)

    # ---- 6. resample
    ego, long_gaps, more = _resample(meas, enu, fx.alt, used, xs, stop_spans, frame, rate_hz,
                                     p, path)
    warnings.extend(more)
    stats = _summary(trace, t, used, long_gaps, stop_spans, ego, warnings, alignment, t0_utc,
                     noise_m, rate_hz, p)
    return ego, stats


@dataclass(slots=True)
class _FixArrays:
    """The fixes as arrays in time order (NaN where a field is absent)."""

    t_utc: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    alt: np.ndarray
    spd: np.ndarray
    crs: np.ndarray
    acc: np.ndarray


def _fix_arrays(trace: GpsTrace) -> _FixArrays:
    n_in = len(trace.fixes)
    if n_in < 2:
        raise InconsistentInputError(trace.path, f"{n_in} GPS fix(es); a trajectory needs at least two",
                         "is the log long enough?")
    fx = trace.fixes

    def col(get) -> np.ndarray:
        return np.array([np.nan if get(f) is None else get(f) for f in fx], float)

    arrays = _FixArrays(col(lambda f: f.t_utc_s), col(lambda f: f.lat_deg),
                        col(lambda f: f.lon_deg), col(lambda f: f.alt_m),
                        col(lambda f: f.speed_mps), col(lambda f: f.course_deg),
                        col(lambda f: f.accuracy_m))
    order = np.argsort(arrays.t_utc, kind="stable")
    if np.any(order != np.arange(n_in)):
        arrays = _FixArrays(*(getattr(arrays, k)[order] for k in _FixArrays.__slots__))
    if np.any(np.diff(arrays.t_utc) <= 0):
        raise InconsistentInputError(trace.path, "fix times do not increase strictly", "duplicate timestamps?")
    return arrays


def _gross_outliers(t: np.ndarray, fx: _FixArrays, p: TraceParams, path) -> np.ndarray:
    """The fixes of the longest physically possible chain (speed gating), found in a
    provisional frame at the median fix; an error when they cannot be one drive."""
    med = Origin(float(np.median(fx.lat)), float(np.median(fx.lon)), 0.0)
    enu = EnuFrame(med).to_enu(fx.lat, fx.lon, np.nan_to_num(fx.alt, nan=0.0))
    # The noise is capped here: fixes of two different places look like enormous noise, and
    # a gate that wide would accept them all.
    sigma_rough = min(_noise_estimate(t, enu[:, :2], np.ones(t.size, bool), p.min_noise_m),
                      p.max_noise_m)
    sig_chain = np.minimum(_sigmas(fx.acc, sigma_rough, p.min_noise_m), p.max_noise_m)
    keep = _consistent_chain(t, enu[:, :2], sig_chain, p.v_max_mps)
    _check_one_drive(t, enu[:, :2], keep, p, path)
    return keep


@dataclass(slots=True)
class _Measurements:
    """What the smoother fuses, per fix: time [s], ENU position [m], its noise [m], the
    reported speed [m/s] and velocity (ENU components, where the course means something),
    and the fixes at which a reported (Doppler) speed says "stopped"."""

    t: np.ndarray
    xy: np.ndarray
    sig: np.ndarray
    spd: np.ndarray
    vel: np.ndarray
    crs_ok: np.ndarray
    crs: np.ndarray
    stops: np.ndarray


def _measurements(t: np.ndarray, xy: np.ndarray, fx: _FixArrays, noise_m: float,
                  keep: np.ndarray, p: TraceParams) -> _Measurements:
    sig = _sigmas(fx.acc, noise_m, p.min_noise_m, keep)
    # Reported velocity as ENU components; course is meaningless when nearly stopped.
    crs_ok = ~np.isnan(fx.crs) & ~np.isnan(fx.spd) & (fx.spd >= 1.0)
    heading_rep = np.deg2rad(90.0 - fx.crs)  # clockwise from north -> CCW from east
    vel = np.column_stack((fx.spd * np.cos(heading_rep), fx.spd * np.sin(heading_rep)))
    return _Measurements(t, xy, sig, fx.spd, vel, crs_ok, fx.crs,
                         doppler_stops(t, fx.spd, keep, p))


def _smooth_part(m: _Measurements, used: np.ndarray, stopped: np.ndarray, p: TraceParams):
    return _smooth_segment(m.t, m.xy, m.sig, m.spd, m.vel, m.crs_ok, used, stopped, p)


def _reject_jumps(m: _Measurements, keep: np.ndarray, p: TraceParams, path
                  ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Smooth each segment (split at long gaps), drop fixes far from the smoothed track,
    smooth again (up to four times); the fixes used and the segments."""
    segments = _segments(m.t, keep, p.segment_gap_s)
    used = keep.copy()
    for seg in segments:
        for _ in range(4):
            xs = _smooth_part(m, used & seg, m.stops, p)
            resid = np.hypot(*(m.xy - xs[:, :2]).T)
            far = resid > np.maximum(p.gate_sigma * m.sig, p.gate_floor_m)
            new_used = used.copy()
            new_used[seg] = keep[seg] & ~far[seg]
            if np.array_equal(new_used, used) or new_used[seg].sum() < 1:
                break
            used = new_used
    if used.sum() < 2:
        raise InconsistentInputError(path, "fewer than two fixes survive outlier rejection",
                         "the trace is too noisy to use")
    return used, segments


def _smooth_with_stops(m: _Measurements, used: np.ndarray, segments: list[np.ndarray],
                       p: TraceParams) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Stops from positions, the final smoothing with zero-velocity updates in them; the
    smoothed states and the stops' (start, end) times."""
    stops_fix = m.stops | position_stops(m.t, m.xy, m.sig, m.spd, used, p)
    xs = np.zeros((m.t.size, 6))
    for seg in segments:
        xs[seg] = _smooth_part(m, used & seg, stops_fix, p)[seg]
    # Spans over the used fixes only: a rejected fix inside a stop must not split it.
    return xs, spans(m.t[used], stops_fix[used], p.stop_min_s)


def _resample(m: _Measurements, enu: np.ndarray, alt: np.ndarray, used: np.ndarray,
              xs: np.ndarray, stop_spans: list[tuple[float, float]], frame: EnuFrame,
              rate_hz: float, p: TraceParams, path
              ) -> tuple[EgoTrack, list[tuple[float, float, float]], list[str]]:
    """The ego at ``rate_hz``: cubic Hermite inside segments, a straight line at constant
    speed across the gaps between them (no motion is invented where there are no fixes),
    standing still in the stops; the gaps bridged and warnings."""
    warnings: list[str] = []
    tu, xu = m.t[used], xs[used]
    k0, k1 = math.ceil(tu[0] * rate_hz - 1e-9), math.floor(tu[-1] * rate_hz + 1e-9)
    if k1 < k0:
        raise InconsistentInputError(path, f"fixes span {tu[-1] - tu[0]:.3f} s, less than one sample at "
                         f"{rate_hz} Hz", "use a higher --rate")
    if k1 - k0 + 1 > MAX_EGO_SAMPLES:
        raise ImpossibleValueError(path, f"{k1 - k0 + 1:,} trajectory samples at {rate_hz:g} Hz, more "
                         f"than the {MAX_EGO_SAMPLES:,} limit", "use a lower --rate")
    tg = np.arange(k0, k1 + 1) / rate_hz
    pos, vel = hermite(tu, xu[:, 0:2], xu[:, 2:4], tg)
    long_gaps = _bridge_gaps(tu, xu[:, 0:2], tg, pos, vel, p.segment_gap_s)
    speed = np.hypot(vel[:, 0], vel[:, 1])
    stopped = np.zeros(len(tg), bool)
    for a, b in stop_spans:
        inside = (tg >= a) & (tg <= b)
        if inside.any():
            stopped |= inside
            pos[inside] = pos[inside].mean(axis=0)  # one place for the whole stop: no creeping
    speed[stopped] = 0.0
    heading = held_heading(vel, speed, stopped, p.heading_min_speed_mps, m.crs)
    if heading is None:
        heading = np.zeros(len(tg))
        warnings.append("the vehicle never moves: heading set to 0 (east)")
    else:
        stop_headings(heading, pos, stopped)
    z = np.interp(tg, tu, median3(enu[used, 2]))
    lat_g, lon_g, _ = frame.to_geodetic(np.column_stack((pos, z)))
    has_alt = bool(np.any(~np.isnan(alt)))
    ego = EgoTrack(origin=frame.origin, t_s=tg, x_m=pos[:, 0], y_m=pos[:, 1],
                   heading_rad=heading, speed_mps=speed, lat_deg=np.asarray(lat_g),
                   lon_deg=np.asarray(lon_g), z_m=z if has_alt else None)
    return ego, long_gaps, warnings


def _summary(trace: GpsTrace, t: np.ndarray, used: np.ndarray,
             long_gaps: list[tuple[float, float, float]], stop_spans: list[tuple[float, float]],
             ego: EgoTrack, warnings: list[str], alignment: str, t0_utc: float, noise_m: float,
             rate_hz: float, p: TraceParams) -> TraceStats:
    """The run's summary: gaps, stops, rejected fixes and the assumptions made."""
    tu = t[used]
    dt_used = np.diff(tu)
    gaps = [(float(tu[i]), float(dt_used[i])) for i in np.flatnonzero(dt_used > p.gap_s)]
    assumptions = []
    for start_s, length_s, chord_m in long_gaps:
        text = (f"GPS gap of {length_s:.0f} s at t={start_s:.1f} s: the ego is placed on the "
                f"straight line between the fixes around it at a constant "
                f"{chord_m / length_s:.1f} m/s ({chord_m:.0f} m)")
        warnings.append(text)
        assumptions.append(text)
    n_in = t.size
    n_rejected = int(n_in - used.sum())
    if n_rejected:
        warnings.append(f"rejected {n_rejected} outlier fixes")
    tg = ego.t_s
    if tg[0] > 0.5 or tg[-1] < 0:
        warnings.append(f"the trajectory starts at video time {tg[0]:.1f} s: the GPS does not "
                        "cover the start of the video")
    return TraceStats(
        format=trace.format, n_fixes=n_in, n_rejected=n_rejected, n_skipped=trace.n_skipped,
        duration_s=float(t[-1] - t[0]),
        distance_m=float(np.hypot(np.diff(ego.x_m), np.diff(ego.y_m)).sum()),
        speed_mean_mps=float(ego.speed_mps.mean()), speed_max_mps=float(ego.speed_mps.max()),
        gaps=gaps, stationary=[(float(a), float(b)) for a, b in stop_spans],
        warnings=warnings, time_alignment=alignment, t0_utc_s=float(t0_utc),
        first_fix_t_s=float(t[0]), noise_m=float(noise_m), rate_hz=float(rate_hz),
        n_samples=len(tg), assumptions=assumptions)


def format_summary(stats: TraceStats, out_path: str | Path | None = None) -> str:
    """A multi-line, human-readable summary of a trace run."""
    lines = [
        f"format:      {stats.format}",
        (f"fixes:       {stats.n_fixes} read, {stats.n_rejected} rejected as outliers, "
         f"{stats.n_skipped} records skipped"),
        f"duration:    {stats.duration_s:.1f} s",
        f"distance:    {stats.distance_m:.1f} m",
        f"speed:       mean {stats.speed_mean_mps:.2f} m/s, max {stats.speed_max_mps:.2f} m/s",
        (f"stopped:     {sum(b - a for a, b in stats.stationary):.1f} s in "
         f"{len(stats.stationary)} stop(s)"),
        "gaps > 2 s:  " + (", ".join(f"{L:.1f} s at t={s:.1f} s" for s, L in stats.gaps[:5])
                            + (f" (+{len(stats.gaps) - 5} more)" if len(stats.gaps) > 5 else "")
                            if stats.gaps else "none"),
        f"noise:       {stats.noise_m:.2f} m (1 sigma, used by the smoother)",
        f"time:        {stats.time_alignment}",
        f"samples:     {stats.n_samples} at {stats.rate_hz:g} Hz",
    ]
    lines += [f"warning:     {w}" for w in stats.warnings]
    if out_path is not None:
        lines.append(f"wrote:       {out_path}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- outliers, noise


def _sigmas(acc: np.ndarray, noise_m: float, floor_m: float,
            keep: np.ndarray | None = None) -> np.ndarray:
    """Per-fix one-sigma position noise [m].

    Reported accuracies mostly describe slowly drifting error, which does not disturb speed;
    they are used only as relative weights, scaled so that their median equals the measured
    white noise ``noise_m``.
    """
    sel = ~np.isnan(acc) & (acc > 0)
    if keep is not None:
        sel_ref = sel & keep
    else:
        sel_ref = sel
    out = np.full(len(acc), noise_m)
    if sel_ref.sum() >= 3:
        scale = noise_m / float(np.median(acc[sel_ref]))
        out[sel] = acc[sel] * scale
    return np.maximum(out, floor_m)


def _noise_estimate(t: np.ndarray, xy: np.ndarray, keep: np.ndarray, floor_m: float) -> float:
    """Robust one-sigma white position noise [m] from each fix's offset to the chord through
    its neighbours (for noise sigma the offset has variance sigma^2 (1 + a^2 + b^2), a + b = 1;
    motion adds only ~acceleration * dt^2 / 4)."""
    tk, pk = t[keep], xy[keep]
    if len(tk) < 3:
        return max(5.0, floor_m)
    dt1, dt2 = np.diff(tk)[:-1], np.diff(tk)[1:]
    span = dt1 + dt2
    ok = span <= 10.0  # across long gaps the chord says nothing about noise
    if ok.sum() < 3:
        ok = np.ones_like(ok)
    a = (dt2 / span)[:, None]
    chord = a * pk[:-2] + (1 - a) * pk[2:]
    r = (pk[1:-1] - chord) / np.sqrt(1 + a**2 + (1 - a) ** 2)
    r = r[ok].ravel()
    mad = float(np.median(np.abs(r - np.median(r))))
    if mad == 0.0:
        # Receivers that repeat positions while stopped make most offsets exactly 0.
        nz = r[r != 0]
        mad = float(np.median(np.abs(nz))) if len(nz) else 0.0
    return max(1.4826 * mad, floor_m)


def _consistent_chain(t: np.ndarray, xy: np.ndarray, sig: np.ndarray, v_max_mps: float,
                      window: int = 100) -> np.ndarray:
    """Mask of the longest chain of fixes in which each step to the next kept fix is
    physically possible: distance <= v_max * dt + 4 sigma-combined + 1 m.

    Dynamic programming over up to ``window`` predecessors: a wild first fix or a burst of
    up to ``window`` bad fixes simply falls off the chain instead of capturing it, which a
    greedy "compare with the last good fix" filter cannot guarantee.
    """
    n = len(t)
    best = np.ones(n, int)
    prev = np.full(n, -1)
    for i in range(1, n):
        j0 = max(0, i - window)
        d = np.hypot(xy[j0:i, 0] - xy[i, 0], xy[j0:i, 1] - xy[i, 1])
        tol = v_max_mps * (t[i] - t[j0:i]) + 4.0 * np.hypot(sig[j0:i], sig[i]) + 1.0
        ok = d <= tol
        if ok.any():
            cand = np.where(ok, best[j0:i], 0)
            # Among equally long chains prefer the predecessor implying the lowest speed: a
            # burst of outliers reachable at 70 m/s must not win a tie against true fixes.
            top = cand == cand.max()
            implied = np.where(top, d / (t[i] - t[j0:i]), np.inf)
            j = j0 + int(np.argmin(implied))
            best[i] = best[j] + 1
            prev[i] = j
    keep = np.zeros(n, bool)
    i = int(np.argmax(best))
    while i >= 0:
        keep[i] = True
        i = prev[i]
    return keep


# --------------------------------------------------------------------------- one drive, gaps

#: Most samples of one ego trajectory: a day at 20 Hz. (The trace's span is limited to a day
#: by the readers; this bounds a high --rate.)
MAX_EGO_SAMPLES = 2_000_000


def _check_one_drive(t: np.ndarray, xy: np.ndarray, keep: np.ndarray, p: TraceParams,
                     path) -> None:
    """Raise :class:`InputError` when the fixes cannot be one drive.

    A few fixes far beyond any car's reach of the kept chain are a receiver's glitches
    (dropped as outliers); more than ``max_wild_share`` of the trace (and at least 3) are
    fixes of other places: two drives in one file, or fixes alternating between two cities.
    The error names the first step between consecutive fixes that no car can drive.
    """
    rejected = np.flatnonzero(~keep)
    idx = np.flatnonzero(keep)
    if rejected.size < 3 or rejected.size <= p.max_wild_share * len(t):
        return
    j = np.searchsorted(t[idx], t[rejected])
    nearest = np.stack((idx[np.clip(j - 1, 0, len(idx) - 1)], idx[np.clip(j, 0, len(idx) - 1)]))
    d = np.hypot(xy[nearest, 0] - xy[rejected, 0], xy[nearest, 1] - xy[rejected, 1])
    reach = p.v_max_mps * np.abs(t[nearest] - t[rejected]) + p.jump_allowance_m
    n_far = int(np.all(d > reach, axis=0).sum())
    if n_far < 3 or n_far <= p.max_wild_share * len(t):
        return
    step = np.hypot(*np.diff(xy, axis=0).T)
    dt = np.diff(t)
    bad = np.flatnonzero(step > p.v_max_mps * dt + p.jump_allowance_m)
    hint = "a trace is one drive: remove the fixes of other places or times"
    if bad.size == 0:
        raise InconsistentInputError(path, f"{n_far} fixes lie farther from the rest of the trace than any "
                         f"car could drive ({p.v_max_mps:g} m/s)", hint)
    k = int(bad[0])
    raise InconsistentInputError(path, f"fix {k + 2} (in time order) is {step[k] / 1000:.1f} km from fix "
                     f"{k + 1}, {dt[k]:.1f} s earlier: {step[k] / dt[k]:,.0f} m/s, beyond any "
                     f"car ({p.v_max_mps:g} m/s); {n_far} fixes lie that far from the rest", hint)


def _segments(t: np.ndarray, keep: np.ndarray, gap_s: float) -> list[np.ndarray]:
    """Masks over all fixes of the pieces of the trace between gaps longer than ``gap_s``
    (between kept fixes); a rejected fix belongs to the piece whose time span holds it."""
    tk = t[keep]
    cuts = tk[:-1][np.diff(tk) > gap_s]  # last kept time before each long gap
    piece = np.searchsorted(cuts, t, side="left")  # fixes at or before a cut stay before it
    return [piece == k for k in range(len(cuts) + 1)]


def _smooth_segment(t, xy, sig, spd, vel_meas, crs_ok, used, stopped, p: TraceParams):
    """:func:`smooth` over the used fixes of one segment; a segment of one fix stands still."""
    if used.sum() >= 2:
        return smooth(t, xy, sig, spd, vel_meas, crs_ok, used, stopped, p)
    out = np.zeros((len(t), 6))
    if used.any():
        out[:, :2] = xy[np.flatnonzero(used)[0]]
    return out


def _bridge_gaps(tu: np.ndarray, pu: np.ndarray, tg: np.ndarray, pos: np.ndarray,
                 vel: np.ndarray, gap_s: float) -> list[tuple[float, float, float]]:
    """Across gaps longer than ``gap_s`` between used fixes (times ``tu``, smoothed positions
    ``pu``), replace the resampled ``pos``/``vel`` (in place) by the straight line at constant
    speed between the fixes either side; return (start_s, length_s, chord_m) of each gap."""
    dt = np.diff(tu)
    out = []
    for i in np.flatnonzero(dt > gap_s):
        a, b = tu[i], tu[i + 1]
        m = (tg > a) & (tg < b)
        chord = pu[i + 1] - pu[i]
        if m.any():
            f = ((tg[m] - a) / (b - a))[:, None]
            pos[m] = pu[i] + f * chord
            vel[m] = chord / (b - a)
        out.append((float(a), float(b - a), float(np.hypot(*chord))))
    return out
