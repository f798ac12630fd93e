"""Stops and headings of the smoothed ego track (:func:`vid2sim.geo.trace.smooth_ego`):
periods standing still, from reported Doppler speed or from fixes that show no net motion,
and the heading held through them."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the parameters' class lives with the smoother that owns them
    from vid2sim.geo.trace import TraceParams


def doppler_stops(t, spd, keep, p: TraceParams) -> np.ndarray:
    """Fixes whose reported (Doppler) speed says "stopped", in runs lasting >= stop_min_s."""
    low = keep & ~np.isnan(spd) & (spd < p.stop_doppler_mps)
    return _runs_mask(t, low, p.stop_min_s)


def position_stops(t, xy, sig, spd, used, p: TraceParams) -> np.ndarray:
    """Fixes inside stops found from positions: maximal runs of fixes whose least-squares
    velocity is not significantly different from 0 (|v| <= max(0.15, 2.5 sigma_v) and below
    ``stop_max_mps``), each new fix lying within 4 sigma of the run's mean position, no
    reported speed above ``2 x stop_doppler_mps``, lasting at least ``stop_min_s``.

    This is a likelihood test of "standing" against "moving on a line": noise alone never
    makes a parked car move, but driving slower than the noise can resolve over the run is
    reported as stopped.
    """
    idx = np.flatnonzero(used)
    tt, pp, ss, vv = t[idx], xy[idx], sig[idx], spd[idx]
    m = len(idx)
    out = np.zeros(len(t), bool)
    if m < 3:
        return out
    # Typical noise around each fix (median over the next 50), for the slope's standard error.
    win = min(50, m)
    padded = np.concatenate((ss, np.full(win - 1, ss[-1])))
    s_meds = np.median(np.lib.stride_tricks.sliding_window_view(padded, win), axis=1)[:m]
    windows: list[tuple[int, int]] = []
    i = 0
    while i < m - 2:
        n = st = stt = 0.0
        sx = np.zeros(2)
        stx = np.zeros(2)
        last_ok = -1
        s_med = float(s_meds[i])
        for j in range(i, m):
            if not np.isnan(vv[j]) and vv[j] > 2.0 * p.stop_doppler_mps:
                break
            tj = tt[j] - tt[i]
            if n >= 1 and np.hypot(*(pp[j] - sx / n)) > 4.0 * ss[j] * math.sqrt(1 + 1 / n) + 0.5:
                break
            n += 1
            st += tj
            stt += tj * tj
            sx += pp[j]
            stx += tj * pp[j]
            if n < 3:
                continue
            var_t = stt - st * st / n  # sum of squared centred times
            v = (stx - st * sx / n) / var_t
            speed = float(np.hypot(*v))
            sigma_v = s_med / np.sqrt(var_t)
            if sigma_v > 0.5 * p.stop_max_mps:
                # Too few fixes to tell standing from slow driving yet: a stop is declared
                # only once motion at stop_max_mps would show as a 2-sigma slope.
                continue
            if speed > min(max(0.15, 2.5 * sigma_v), p.stop_max_mps):
                break
            last_ok = j
        if last_ok >= 0 and tt[last_ok] - tt[i] >= p.stop_min_s:
            if windows and i <= windows[-1][1] + 1:
                windows[-1] = (windows[-1][0], max(windows[-1][1], last_ok))
            else:
                windows.append((i, last_ok))
            if last_ok == m - 1:
                break
            # A window that began in the braking before a stop can fail before the stop ends;
            # windows starting later get their own chance (stepping by a quarter keeps long
            # stops at 10 Hz affordable).
            i += max(1, (last_ok - i) // 4)
        else:
            i += 1
    # Overlapping windows belong to one stop; its ends are then placed once.
    for i, j in windows:
        a, b = _refine_stop(tt, pp, i, j)
        if tt[b] - tt[a] >= p.stop_min_s:
            out[idx[a:b + 1]] = True
    return _merge_stops(tt, pp, ss, idx, out)


def _merge_stops(tt, pp, ss, idx, out) -> np.ndarray:
    """Join two stops separated by at most 10 s when their mean positions agree within
    noise and every fix between lies near them: one noisy fix must not split a stop into two
    with invented motion in between."""
    runs = _run_bounds(out[idx])
    k = 0
    while k + 1 < len(runs):
        (a1, b1), (a2, b2) = runs[k], runs[k + 1]
        p1, p2 = pp[a1:b1].mean(axis=0), pp[a2:b2].mean(axis=0)
        s = float(np.median(ss[a1:b2]))
        merged = pp[a1:b2].mean(axis=0)
        between = pp[b1:a2]
        if (tt[a2] - tt[b1 - 1] <= 10.0
                and np.hypot(*(p1 - p2)) <= max(1.0, 3.0 * s * math.sqrt(1 / (b1 - a1) + 1 / (b2 - a2)))
                and np.all(np.hypot(*(between - merged).T) <= 4.0 * s + 0.5)):
            out[idx[a1:b2]] = True
            runs[k:k + 2] = [(a1, b2)]
        else:
            k += 1
    return out


def _refine_stop(tt: np.ndarray, pp: np.ndarray, a: int, b: int,
                 k_in: int = 8, k_out: int = 6) -> tuple[int, int]:
    """Move the ends of the stop ``a..b`` (fix indices) to the best change points.

    The slope test accepts a little of the braking before and the pulling away after a stop
    (slow motion is within its noise). Near each end, fixes are modelled as standing at the
    stop's mean position up to fix k and, beyond it, as starting (or ending) a constant
    acceleration from rest, x = P + c (t - t_k)^2 per axis; the k with the smallest squared
    residual over the same window wins.
    """
    m = len(tt)

    def ssr(k: int, lo: int, hi: int, leaving: bool) -> float:
        stay = slice(lo, k + 1) if leaving else slice(k, hi + 1)
        move = slice(k + 1, hi + 1) if leaving else slice(lo, k)
        rs = pp[stay] - pp[stay].mean(axis=0)
        total = float(np.sum(rs * rs))
        if move.stop > move.start:
            w = (tt[move] - tt[k]) ** 2
            d = pp[move] - pp[stay].mean(axis=0)
            c = (w @ d) / float(w @ w)
            r = d - np.outer(w, c)
            total += float(np.sum(r * r))
        return total

    if b < m - 1:
        lo, hi = max(a, b - k_in), min(m - 1, b + k_out)
        ks = range(max(a + 2, lo), b + 1)
        if len(ks):
            b = min(ks, key=lambda k: ssr(k, max(a, lo - k_in), hi, True))
    if a > 0:
        lo, hi = max(0, a - k_out), min(b, a + k_in)
        ks = range(a, min(b - 2, hi) + 1)
        if len(ks):
            a = min(ks, key=lambda k: ssr(k, lo, min(b, hi + k_in), False))
    return a, b


def _run_bounds(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index pairs of the True runs of ``mask``."""
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def _runs_mask(t, mask, min_s) -> np.ndarray:
    out = np.zeros(len(mask), bool)
    for a, b in _run_bounds(mask):
        if t[b - 1] - t[a] >= min_s:
            out[a:b] = True
    return out


def spans(t, mask, min_s) -> list[tuple[float, float]]:
    """(t_start, t_end) of the True runs of ``mask`` lasting at least ``min_s``."""
    return [(float(t[a]), float(t[b - 1])) for a, b in _run_bounds(mask)
            if t[b - 1] - t[a] >= min_s]


def held_heading(vel, speed, stopped, min_speed, crs) -> np.ndarray | None:
    """Heading CCW from east [rad] from the velocity where moving; held (carried forward,
    or back from the first motion) where stopped or too slow for the velocity's direction to
    mean anything."""
    moving = ~stopped & (speed >= min_speed)
    heading = np.arctan2(vel[:, 1], vel[:, 0])
    if not moving.any():
        ok = ~np.isnan(crs)
        if ok.any():
            return np.full(len(speed), math.atan2(*_course_to_enu(float(crs[ok][0]))[::-1]))
        return None
    idx = np.where(moving, np.arange(len(speed)), -1)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.argmax(moving))
    idx[idx < 0] = first
    return heading[idx]


def stop_headings(heading: np.ndarray, pos: np.ndarray, stopped: np.ndarray,
                  baseline_m: float = 10.0) -> None:
    """Give each stop the direction of the last ``baseline_m`` metres driven into it (or, for
    a stop at the start, the first metres driven out of it), in place.

    Near a stop the velocity is small and its direction noisy; a chord over 10 m of smoothed
    path is a far steadier estimate of where the car points while it stands.
    """
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pos, axis=0).T))))
    for a, b in _run_bounds(stopped):
        before = np.flatnonzero(s[:a] <= s[a] - baseline_m)
        after = np.flatnonzero(s[b:] >= s[b - 1] + baseline_m)
        if len(before):
            k = before[-1]
            d = pos[a] - pos[k]
        elif len(after):
            k = b + after[0]
            d = pos[k] - pos[b - 1]
        else:
            continue
        heading[a:b] = math.atan2(d[1], d[0])


def _course_to_enu(course_deg: float) -> tuple[float, float]:
    """Unit vector (east, north) of a course clockwise from north."""
    c = math.radians(course_deg)
    return math.sin(c), math.cos(c)


def median3(a: np.ndarray) -> np.ndarray:
    """Running median of 3 (altitude spikes), ends unchanged."""
    if len(a) < 3:
        return a.copy()
    out = a.copy()
    out[1:-1] = np.median(np.stack((a[:-2], a[1:-1], a[2:])), axis=0)
    return out
