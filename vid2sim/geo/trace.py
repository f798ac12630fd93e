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

from vid2sim.errors import InputError
from vid2sim.fileio import atomic_open
from vid2sim.geo.frames import EnuFrame
from vid2sim.geo.stops import (
    doppler_stops,
    held_heading,
    median3,
    position_stops,
    spans,
    stop_headings,
)
from vid2sim.records import EgoTrack, GpsTrace, Origin, TraceStats


@dataclass(frozen=True, slots=True)
class TraceParams:
    """Tuning of :func:`smooth_ego`; the defaults suit road vehicles.

    :param v_max_mps: fastest plausible speed; faster steps between fixes are outliers [m/s]
    :param jerk_psd: white-jerk power spectral density of the constant-acceleration model
        [m^2/s^5]; larger follows manoeuvres faster but passes more noise into speed
    :param gate_sigma: a fix farther than this many sigmas from the smoothed track is dropped
    :param gate_floor_m: ...but never one closer than this [m] (protects very precise traces
        from rejecting model mismatch)
    :param speed_sigma_mps: one-sigma error of a reported speed [m/s]
    :param course_sigma_deg: one-sigma error of a reported course [deg]
    :param stop_doppler_mps: reported speeds below this mean the vehicle is stopped [m/s]
    :param stop_min_s: shortest stop that is detected [s]
    :param stop_max_mps: a run of fixes moving faster than this is never called a stop [m/s]
    :param heading_min_speed_mps: below this speed the heading is held, not taken from noise
    :param gap_s: a time between accepted fixes longer than this is reported as a gap [s]
    :param min_noise_m: floor of the position noise [m]
    :param noise_m: white position noise [m] if known; default estimated from the fixes
    """

    v_max_mps: float = 70.0
    jerk_psd: float = 0.1
    gate_sigma: float = 4.5
    gate_floor_m: float = 0.5
    speed_sigma_mps: float = 0.3
    course_sigma_deg: float = 5.0
    stop_doppler_mps: float = 0.25
    stop_min_s: float = 1.5
    stop_max_mps: float = 1.0
    heading_min_speed_mps: float = 0.5
    gap_s: float = 2.0
    min_noise_m: float = 0.02
    noise_m: float | None = None


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


def smooth_ego(trace: GpsTrace, rate_hz: float = 10.0, gps_offset_s: float | None = None,
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
        raise InputError(path, f"output rate {rate_hz} Hz must be > 0")
    n_in = len(trace.fixes)
    if n_in < 2:
        raise InputError(path, f"{n_in} GPS fix(es); a trajectory needs at least two",
                         "is the log long enough?")
    warnings = list(trace.warnings)
    fx = trace.fixes
    t_utc = np.array([f.t_utc_s for f in fx], float)
    lat = np.array([f.lat_deg for f in fx], float)
    lon = np.array([f.lon_deg for f in fx], float)
    alt = np.array([np.nan if f.alt_m is None else f.alt_m for f in fx], float)
    spd = np.array([np.nan if f.speed_mps is None else f.speed_mps for f in fx], float)
    crs = np.array([np.nan if f.course_deg is None else f.course_deg for f in fx], float)
    acc = np.array([np.nan if f.accuracy_m is None else f.accuracy_m for f in fx], float)
    order = np.argsort(t_utc, kind="stable")
    if np.any(order != np.arange(n_in)):
        t_utc, lat, lon, alt, spd, crs, acc = (a[order] for a in (t_utc, lat, lon, alt, spd, crs, acc))
    if np.any(np.diff(t_utc) <= 0):
        raise InputError(path, "fix times do not increase strictly", "duplicate timestamps?")

    # ---- 1. time alignment
    t0_utc, alignment = video_t0_utc(trace, gps_offset_s)
    if gps_offset_s is None and trace.video_start_utc_s is not None \
            and not (t_utc[0] - 3600 <= t0_utc <= t_utc[-1] + 3600):
        warnings.append("the file's video start is more than an hour outside the fixes; "
                        "check the clock or pass --gps-offset")
    t = t_utc - t0_utc

    too_fast = spd > p.v_max_mps
    if np.any(too_fast):
        warnings.append(f"ignored {int(too_fast.sum())} reported speeds above {p.v_max_mps} m/s")
        spd[too_fast] = np.nan

    # ---- 2. gross outliers (speed gating), in a provisional frame at the median fix
    med = Origin(float(np.median(lat)), float(np.median(lon)), 0.0)
    enu = EnuFrame(med).to_enu(lat, lon, np.nan_to_num(alt, nan=0.0))
    sigma_rough = _noise_estimate(t, enu[:, :2], np.ones(n_in, bool), p.min_noise_m)
    keep = _consistent_chain(t, enu[:, :2], _sigmas(acc, sigma_rough, p.min_noise_m), p.v_max_mps)

    # ---- ENU frame at the origin (first accepted fix by default)
    if origin is None:
        i0 = int(np.flatnonzero(keep)[0])
        origin = Origin(float(lat[i0]), float(lon[i0]), 0.0 if np.isnan(alt[i0]) else float(alt[i0]))
    frame = EnuFrame(origin)
    alt_filled = np.where(np.isnan(alt), origin.alt, alt)
    enu = frame.to_enu(lat, lon, alt_filled)
    xy = enu[:, :2]

    # ---- 3. position noise
    noise_m = p.noise_m or _noise_estimate(t, xy, keep, p.min_noise_m)
    sig = _sigmas(acc, noise_m, p.min_noise_m, keep)

    # Reported velocity as ENU components; course is meaningless when nearly stopped.
    crs_ok = ~np.isnan(crs) & ~np.isnan(spd) & (spd >= 1.0)
    heading_rep = np.deg2rad(90.0 - crs)  # clockwise from north -> CCW from east
    vel_meas = np.column_stack((spd * np.cos(heading_rep), spd * np.sin(heading_rep)))

    # ---- 4. smooth, drop fixes far from the smoothed track, smooth again
    stops_fix = doppler_stops(t, spd, keep, p)
    used = keep.copy()
    for _ in range(4):
        xs = _smooth(t, xy, sig, spd, vel_meas, crs_ok, used, stops_fix, p)
        resid = np.hypot(*(xy - xs[:, :2]).T)
        far = resid > np.maximum(p.gate_sigma * sig, p.gate_floor_m)
        new_used = keep & ~far
        if np.array_equal(new_used, used):
            break
        used = new_used
    if used.sum() < 2:
        raise InputError(path, "fewer than two fixes survive outlier rejection",
                         "the trace is too noisy to use")

    # ---- 5. stops from positions; final smoothing with zero-velocity updates
    stops_fix = stops_fix | position_stops(t, xy, sig, spd, used, p)
    xs = _smooth(t, xy, sig, spd, vel_meas, crs_ok, used, stops_fix, p)
    # Spans over the used fixes only: a rejected fix inside a stop must not split it.
    stop_spans = spans(t[used], stops_fix[used], p.stop_min_s)

    # ---- 6. resample
    tu, xu = t[used], xs[used]
    k0, k1 = math.ceil(tu[0] * rate_hz - 1e-9), math.floor(tu[-1] * rate_hz + 1e-9)
    if k1 < k0:
        raise InputError(path, f"fixes span {tu[-1] - tu[0]:.3f} s, less than one sample at "
                         f"{rate_hz} Hz", "use a higher --rate")
    tg = np.arange(k0, k1 + 1) / rate_hz
    pos, vel = _hermite(tu, xu[:, 0:2], xu[:, 2:4], tg)
    speed = np.hypot(vel[:, 0], vel[:, 1])
    stopped = np.zeros(len(tg), bool)
    for a, b in stop_spans:
        m = (tg >= a) & (tg <= b)
        if m.any():
            stopped |= m
            pos[m] = pos[m].mean(axis=0)  # one place for the whole stop: no creeping
    speed[stopped] = 0.0
    heading = held_heading(vel, speed, stopped, p.heading_min_speed_mps, crs)
    if heading is None:
        heading = np.zeros(len(tg))
        warnings.append("the vehicle never moves: heading set to 0 (east)")
    else:
        stop_headings(heading, pos, stopped)

    z = np.interp(tg, tu, median3(enu[used, 2]))
    lat_g, lon_g, _ = frame.to_geodetic(np.column_stack((pos, z)))
    has_alt = bool(np.any(~np.isnan(alt)))
    ego = EgoTrack(origin=origin, t_s=tg, x_m=pos[:, 0], y_m=pos[:, 1], heading_rad=heading,
                   speed_mps=speed, lat_deg=np.asarray(lat_g), lon_deg=np.asarray(lon_g),
                   z_m=z if has_alt else None)

    # ---- summary
    dt_used = np.diff(tu)
    gap_mask = dt_used > p.gap_s
    gaps = [(float(tu[i]), float(dt_used[i])) for i in np.flatnonzero(gap_mask)]
    n_rejected = int(n_in - used.sum())
    if n_rejected:
        warnings.append(f"rejected {n_rejected} outlier fixes")
    if tg[0] > 0.5 or tg[-1] < 0:
        warnings.append(f"the trajectory starts at video time {tg[0]:.1f} s: the GPS does not "
                        "cover the start of the video")
    stats = TraceStats(
        format=trace.format, n_fixes=n_in, n_rejected=n_rejected, n_skipped=trace.n_skipped,
        duration_s=float(t[-1] - t[0]),
        distance_m=float(np.hypot(np.diff(pos[:, 0]), np.diff(pos[:, 1])).sum()),
        speed_mean_mps=float(speed.mean()), speed_max_mps=float(speed.max()),
        gaps=gaps, stationary=[(float(a), float(b)) for a, b in stop_spans],
        warnings=warnings, time_alignment=alignment, t0_utc_s=float(t0_utc),
        first_fix_t_s=float(t[0]), noise_m=float(noise_m), rate_hz=float(rate_hz),
        n_samples=len(tg))
    return ego, stats


def write_ego_csv(ego: EgoTrack, path: str | Path) -> None:
    """Write ``t_s,lat,lon,x_m,y_m,heading_rad,speed_mps`` atomically with fixed decimals
    (mm in position, 1e-8 deg ~ 1 mm in lat/lon), so identical input gives identical bytes."""
    cols = (
        (ego.t_s, 3), (ego.lat_deg, 8), (ego.lon_deg, 8), (ego.x_m, 3), (ego.y_m, 3),
        (ego.heading_rad, 5), (ego.speed_mps, 3),
    )
    # Adding 0.0 after rounding turns -0.0 into 0.0, so "-0.000" never appears.
    cells = [[f"{v:.{d}f}" for v in (np.round(np.asarray(a, float), d) + 0.0)] for a, d in cols]
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("t_s,lat,lon,x_m,y_m,heading_rad,speed_mps\n")
        for row in zip(*cells, strict=True):
            fh.write(",".join(row) + "\n")


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


def run_trace(gps_file: str | Path, out_path: str | Path, rate_hz: float = 10.0,
              gps_offset_s: float | None = None) -> str:
    """Read ``gps_file``, smooth it, write ``out_path`` (ego.csv) and return a summary."""
    from vid2sim.geo.readers import read_gps

    if Path(out_path).is_dir():
        raise InputError(out_path, "is a folder", "give the output file name, e.g. ego.csv")
    trace = read_gps(Path(gps_file))
    ego, stats = smooth_ego(trace, rate_hz=rate_hz, gps_offset_s=gps_offset_s)
    write_ego_csv(ego, out_path)
    return format_summary(stats, out_path)


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


# --------------------------------------------------------------------------- Kalman / RTS

# State: [x, y, vx, vy, ax, ay] in ENU [m, m/s, m/s^2]; constant acceleration driven by white
# jerk (Bar-Shalom, Estimation with Applications to Tracking and Navigation, sec. 6.3.3).


def _transitions(dt: np.ndarray, q: float) -> tuple[np.ndarray, np.ndarray]:
    """(M, 6, 6) transition and process-noise matrices for steps of ``dt`` seconds."""
    m = len(dt)
    f1 = np.zeros((m, 3, 3))
    f1[:, 0, 0] = f1[:, 1, 1] = f1[:, 2, 2] = 1.0
    f1[:, 0, 1] = f1[:, 1, 2] = dt
    f1[:, 0, 2] = 0.5 * dt * dt
    q1 = np.empty((m, 3, 3))
    q1[:, 0, 0] = dt**5 / 20
    q1[:, 0, 1] = q1[:, 1, 0] = dt**4 / 8
    q1[:, 0, 2] = q1[:, 2, 0] = dt**3 / 6
    q1[:, 1, 1] = dt**3 / 3
    q1[:, 1, 2] = q1[:, 2, 1] = dt**2 / 2
    q1[:, 2, 2] = dt
    q1 *= q
    # The x and y axes are independent in the model: interleave the 3x3 blocks.
    f = np.zeros((m, 6, 6))
    qq = np.zeros((m, 6, 6))
    for axis in (0, 1):
        f[:, axis::2, axis::2] = f1
        qq[:, axis::2, axis::2] = q1
    return f, qq


def _update_block(x: np.ndarray, P: np.ndarray, z: np.ndarray, lo: int,
                  R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with a measurement of state elements ``lo`` and ``lo + 1`` (positions
    at 0, velocities at 2); a 2x2 innovation covariance inverted in closed form."""
    S = P[lo:lo + 2, lo:lo + 2] + R
    det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    s_inv = np.array([[S[1, 1], -S[0, 1]], [-S[1, 0], S[0, 0]]]) / det
    K = P[:, lo:lo + 2] @ s_inv
    x = x + K @ (z - x[lo:lo + 2])
    P = P - K @ P[lo:lo + 2, :]
    # Re-symmetrise: the tiny zero-velocity variances would otherwise let rounding build up.
    return x, 0.5 * (P + P.T)


def _update_scalar(x: np.ndarray, P: np.ndarray, z: float, h: np.ndarray,
                   r: float) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with one scalar measurement z = h . x + noise of variance r."""
    ph = P @ h
    k = ph / (h @ ph + r)
    x = x + k * (z - h @ x)
    P = P - np.outer(k, ph)
    return x, 0.5 * (P + P.T)


def _smooth(t, xy, sig, spd, vel_meas, crs_ok, used, stopped, p: TraceParams):
    """Forward Kalman filter + RTS smoother over the used fixes; returns the smoothed state
    [x, y, vx, vy, ax, ay] at ALL fixes (unused ones get the Hermite interpolation of their
    used neighbours, acceleration 0)."""
    idx = np.flatnonzero(used)
    m = len(idx)
    xf = np.zeros((m, 6))
    pf = np.zeros((m, 6, 6))
    xp = np.zeros((m, 6))
    pp = np.zeros((m, 6, 6))
    fs, qs = _transitions(np.diff(t[idx], prepend=t[idx[0]]), p.jerk_psd)
    x = np.zeros(6)
    x[:2] = xy[idx[0]]
    P = np.diag([sig[idx[0]] ** 2] * 2 + [30.0**2] * 2 + [3.0**2] * 2)
    cs = math.radians(p.course_sigma_deg)
    zupt_r = np.eye(2) * 1e-4
    for k, i in enumerate(idx):
        if k > 0:
            F = fs[k]
            x = F @ x
            P = F @ P @ F.T + qs[k]
        xp[k], pp[k] = x, P
        x, P = _update_block(x, P, xy[i], 0, np.eye(2) * sig[i] ** 2)
        if stopped[i]:
            # Zero-velocity update: the vehicle is known to stand still.
            x, P = _update_block(x, P, np.zeros(2), 2, zupt_r)
        elif crs_ok[i]:
            v = vel_meas[i]
            s = float(spd[i])
            u = v / s  # along-track unit vector
            n = np.array([-u[1], u[0]])
            R = (np.outer(u, u) * p.speed_sigma_mps**2
                 + np.outer(n, n) * max(s * cs, p.speed_sigma_mps) ** 2)
            x, P = _update_block(x, P, v, 2, R)
        elif not np.isnan(spd[i]):
            # Speed without course: |v| = s, linearised about the current velocity.
            vn = float(np.hypot(x[2], x[3]))
            if vn > 0.5:
                h = np.zeros(6)
                h[2:4] = x[2:4] / vn
                x, P = _update_scalar(x, P, float(spd[i]) - vn + float(h @ x), h,
                                      p.speed_sigma_mps**2)
        xf[k], pf[k] = x, P
    xs = xf.copy()
    if m > 1:
        # RTS gains for all steps at once: C_k = P_f,k F_k+1^T P_p,k+1^-1.
        gains = np.linalg.solve(pp[1:], fs[1:] @ pf[:-1]).transpose(0, 2, 1)
        for k in range(m - 2, -1, -1):
            xs[k] = xf[k] + gains[k] @ (xs[k + 1] - xp[k + 1])
    # Spread to all fixes: rejected ones get the Hermite interpolation of their neighbours.
    out = np.zeros((len(t), 6))
    pos, vel = _hermite(t[idx], xs[:, :2], xs[:, 2:4], t)
    out[:, :2], out[:, 2:4] = pos, vel
    out[idx] = xs
    return out


def _hermite(tk: np.ndarray, pk: np.ndarray, vk: np.ndarray,
             tq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite interpolation of positions ``pk`` with derivatives ``vk`` at ``tq``;
    returns positions and their time derivative (clamped to the ends outside ``tk``)."""
    tq = np.clip(tq, tk[0], tk[-1])
    j = np.clip(np.searchsorted(tk, tq, side="right") - 1, 0, len(tk) - 2)
    h = (tk[j + 1] - tk[j])[:, None]
    s = ((tq - tk[j])[:, None]) / h
    p0, p1, v0, v1 = pk[j], pk[j + 1], vk[j], vk[j + 1]
    s2, s3 = s * s, s * s * s
    pos = ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * h * v0
           + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * h * v1)
    vel = ((6 * s2 - 6 * s) * p0 / h + (3 * s2 - 4 * s + 1) * v0
           + (-6 * s2 + 6 * s) * p1 / h + (3 * s2 - 2 * s) * v1)
    return pos, vel
