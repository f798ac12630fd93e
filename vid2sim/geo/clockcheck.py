"""GPS clock integrity: the fixes' time stamps checked against the order the receiver wrote
them in and against where they are.

Sorting fixes by their time stamps is right when a few records were written late, and wrong
when the receiver's clock jumped: a clock that steps back 6 s while the car drives on at
11 m/s puts every fix of those 6 s beside one 66 m away at the same time, and sorted by
time that reads as 27 m/s of driving back and forth that never happened. The positions tell
the two apart. :func:`repair_clock` reads the fixes in file order and, at each time stamp
that goes back,

- sorts the records by time (records that arrived out of order), or
- re-times the fixes after the step so that they follow the fix before it by one sampling
  interval (a clock that jumped back while the positions say the car drove on),

as the times say: records written late fill holes (missing samples) in the times before
them, while after a clock jump back their times crowd in among fixes already there. A
reading whose steps are faster than the trace itself shows elsewhere is not taken (the
other is, if it fits);

a time stamp that jumps forward while the car provably kept moving (too little way between
the two fixes to brake to a stop and pull away again) is re-timed the same way. Fixes with
one time at different places keep the one that lies on the way between its neighbours.
Every change is a warning that names the fixes (numbered from 1 in file order); a trace
that no reading makes consistent, or whose clock jumps more than ``max_jumps`` times, is an
:class:`~vid2sim.base.errors.InconsistentInputError`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vid2sim.base.errors import InconsistentInputError

#: metres per degree of latitude (WGS-84 mean): positions here only need to be good to a
#: fraction of a metre over a few hundred metres, so a local flat projection does
_M_PER_DEG = 111_320.0


@dataclass(frozen=True, slots=True)
class ClockParams:
    """Tuning of :func:`repair_clock`.

    :param step_noise_m: how far apart two fixes of one place may be: 3 sigma of the
        difference of two consumer fixes (5 m one-sigma per axis: sqrt(2) x 5 x 2.1 ~ 15 m)
        [m]; steps shorter than this say nothing about motion
    :param speed_margin: a step is consistent when its speed, after ``step_noise_m``, is
        within this factor of the fastest speed the trace shows between fixes in order (the
        issue's bar: no speed beyond 1.5 x the fixes' own)
    :param min_speed_mps: ...and always when it is below this: a trace that stands still
        still has noise [m/s]
    :param max_accel_mps2: hardest braking / acceleration of a car in traffic (about 0.3 g;
        emergency braking reaches 0.8-1 g, everyday driving stays below 0.3 g): a car that
        stops between two fixes needs ``v^2 / (2 a)`` to brake and again to pull away [m/s^2]
    :param moving_mps: a forward jump is only called where the car moved at least this fast
        on both sides [m/s]
    :param max_jumps: more clock jumps than this, and the trace has no time base to repair
    """

    step_noise_m: float = 15.0
    speed_margin: float = 1.5
    min_speed_mps: float = 3.0
    max_accel_mps2: float = 3.0
    moving_mps: float = 3.0
    max_jumps: int = 5


@dataclass(slots=True)
class ClockRepair:
    """What :func:`repair_clock` made of a trace.

    :param keep: indices into the file-order fixes, in the repaired time order
    :param t_s: their repaired times [s, same clock as the input]
    :param warnings: one line per change, naming the fixes
    """

    keep: np.ndarray
    t_s: np.ndarray
    warnings: list[str] = field(default_factory=list)


def local_xy(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """Flat east/north metres about the first fix (good to 0.1 % over tens of km)."""
    lat, lon = np.asarray(lat_deg, float), np.asarray(lon_deg, float)
    if not lat.size:
        return np.zeros((0, 2))
    k = math.cos(math.radians(float(lat[0])))
    return np.column_stack([(lon - lon[0]) * _M_PER_DEG * k, (lat - lat[0]) * _M_PER_DEG])


def repair_clock(t_s: np.ndarray, xy_m: np.ndarray, path: str | Path | None = None,
                 params: ClockParams | None = None) -> ClockRepair:
    """Put fixes given in file order on a consistent clock (see the module docs).

    Parameters
    ----------
    t_s : time stamp of each fix, in file order [s]
    xy_m : its position in flat metres (:func:`local_xy`), (N, 2)
    path : the file, for errors
    params : tuning

    Raises
    ------
    InconsistentInputError
        where neither the time order nor the file order gives consistent steps, or the
        clock jumps more than ``max_jumps`` times.
    """
    p = params or ClockParams()
    t = np.asarray(t_s, float).copy()
    xy = np.asarray(xy_m, float).reshape(-1, 2)
    order = np.arange(t.size)
    warnings: list[str] = []
    if t.size < 2:
        return ClockRepair(order, t, warnings)
    limit = _speed_limit(t, xy, p)
    jumps, late = 0, []
    if np.count_nonzero(np.diff(t) < 0) > MANY_STEPS_BACK:
        t, order, late = _sorted_whole(t, xy, limit, path, p)
    while True:
        back = np.flatnonzero(np.diff(t) < 0)
        if not back.size:
            break
        k = int(back[0])
        resorted, moved = _sorted_reading(t, k)
        shifted = _retimed_reading(t, k)
        sort_fits = _moved_fit(t[resorted], xy[order[resorted]], resorted, k, moved, limit, p)
        shift_fits = _step_fits(shifted, xy[order], k, limit, p)
        if not (sort_fits or shift_fits):
            _refuse(path, order, t, xy, k, limit)
        # records written late fill holes in the times before them; after a clock jump
        # their times crowd in among fixes already there
        prefer_sort = not _crowded(t, k, moved)
        if sort_fits and (not shift_fits or prefer_sort):
            # ties: the time stamps are right, the records were written late
            late.extend(order[k + 1:k + 1 + moved].tolist())
            t, order = t[resorted], order[resorted]
            continue
        jumps += 1
        if jumps > p.max_jumps:
            raise InconsistentInputError(path, f"the receiver clock jumps back more than "
                                         f"{p.max_jumps} times", "no consistent time base: "
                                         "fix the log's times or use another recording")
        warnings.append(_jump_warning(order, t, shifted, k, "back"))
        t = shifted
    if late:
        warnings.append(f"{_names(late)} were not in time order (written late); sorted them "
                        "by time (their positions fit there)")
    t, order, more = _forward_jumps(t, xy, order, p, jumps)
    warnings.extend(more)
    keep, dropped = _one_fix_per_time(t, xy[order], p)
    warnings.extend(_duplicate_warnings(order, dropped, keep))
    return ClockRepair(order[keep], t[keep], warnings)


# --------------------------------------------------------------------------- readings

#: more steps back in time than this are not read one by one: the trace is sorted by time
#: as a whole if that leaves it consistent, else refused
MANY_STEPS_BACK = 50


def _sorted_whole(t: np.ndarray, xy: np.ndarray, limit: float, path, p: ClockParams
                  ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """The whole trace sorted by time, when its steps are then no less consistent than the
    file order's forward steps (records written in a scrambled order)."""
    order = np.argsort(t, kind="stable")
    dt_file = np.diff(t)
    fwd = np.flatnonzero(dt_file > 0)
    bad_file = sum(_step_speed(t, xy, i, i + 1, p) > limit for i in fwd.tolist())
    ts, xs = t[order], xy[order]
    bad_sorted = sum(_step_speed(ts, xs, i, i + 1, p) > limit for i in range(t.size - 1))
    if bad_sorted > bad_file + MANY_STEPS_BACK // 10:
        raise InconsistentInputError(path, f"the time stamps go back {dt_file.size - fwd.size} "
                                     "times and neither their order nor the file's gives one "
                                     "consistent drive", "the receiver clock is broken: fix "
                                     "the log's times")
    return ts, order, np.flatnonzero(order != np.arange(t.size)).tolist()



def _speed_limit(t: np.ndarray, xy: np.ndarray, p: ClockParams) -> float:
    """Fastest speed a step may show [m/s]: ``speed_margin`` x the fastest the trace shows
    between consecutive fixes in order (90th percentile, noise allowed for)."""
    dt = np.diff(t)
    d = np.hypot(*np.diff(xy, axis=0).T)
    ok = dt > 0
    if not ok.any():
        return p.min_speed_mps
    v = np.maximum(d[ok] - p.step_noise_m, 0.0) / dt[ok]
    return max(p.speed_margin * float(np.percentile(v, 90)), p.min_speed_mps)


def _sorted_reading(t: np.ndarray, k: int) -> tuple[np.ndarray, int]:
    """Order of the records with those after ``k`` that are earlier than ``k`` moved into
    their place by time; how many moved."""
    m = k + 1
    while m < t.size and t[m] < t[k]:
        m += 1
    head = np.argsort(t[:m], kind="stable")
    return np.concatenate([head, np.arange(m, t.size)]), m - k - 1


def _period(t: np.ndarray, k: int) -> float:
    """The receiver's sampling interval near record ``k`` [s]: the median forward step,
    leaving out the steps next to a step back (a record written one place late makes the
    steps around it two intervals long, and three such swaps in 20 records would double
    the estimate)."""
    dt = np.diff(t[max(0, k - 10):k + 12])
    back = dt < 0
    beside = back.copy()
    beside[1:] |= back[:-1]
    beside[:-1] |= back[1:]
    clean = dt[(dt > 0) & ~beside]
    dt = clean if clean.size else dt[dt > 0]
    return float(np.median(dt)) if dt.size else 1.0


def _retimed_reading(t: np.ndarray, k: int) -> np.ndarray:
    """Times with every record after ``k`` shifted to follow ``k`` by one interval."""
    out = t.copy()
    out[k + 1:] += t[k] - t[k + 1] + _period(t, k)
    return out


def _step_speed(t: np.ndarray, xy: np.ndarray, a: int, b: int, p: ClockParams) -> float:
    """Speed of the step from record ``a`` to ``b`` beyond the noise [m/s] (inf for a step
    of no time between different places)."""
    excess = max(float(np.hypot(*(xy[b] - xy[a]))) - p.step_noise_m, 0.0)
    dt = float(t[b] - t[a])
    return excess / dt if dt > 0 else (math.inf if excess > 0 else 0.0)


def _crowded(t: np.ndarray, k: int, moved: int) -> bool:
    """Whether most of the ``moved`` records after ``k`` have times where the fixes before
    them miss no sample (their neighbours in time at most 1.5 intervals apart): a clock
    that went back, not records that arrived late into a hole."""
    if not moved:
        return False
    before = np.sort(t[:k + 1])
    late = t[k + 1:k + 1 + moved]
    j = np.searchsorted(before, late)
    lo = before[np.clip(j - 1, 0, before.size - 1)]
    hi = before[np.clip(j, 0, before.size - 1)]
    # the interval from the times in order: records written late lengthen the file-order
    # steps around them, which would hide the hole they fill
    near = np.diff(np.sort(t[max(0, k - 10):k + 12]))
    near = near[near > 0]
    period = min(_period(t, k), float(np.median(near))) if near.size else _period(t, k)
    no_hole = ((hi - lo) <= 1.5 * period) & (late > before[0])  # earlier than all: no
    return int(np.count_nonzero(no_hole)) * 2 >= moved


def _moved_fit(t: np.ndarray, xy: np.ndarray, resorted: np.ndarray, k: int, moved: int,
               limit: float, p: ClockParams) -> bool:
    """Whether the records moved by sorting fit where their times put them: at most one
    step to or from them (one of them may be an outlier) is too fast."""
    where = np.flatnonzero((resorted > k) & (resorted <= k + moved))
    steps = {(i - 1, i) for i in where if i > 0} | {(i, i + 1) for i in where
                                                     if i + 1 < t.size}
    return sum(_step_speed(t, xy, a, b, p) > limit for a, b in steps) <= 1


def _step_fits(t: np.ndarray, xy: np.ndarray, k: int, limit: float, p: ClockParams) -> bool:
    """Whether the re-timed step from record ``k`` on is within ``limit`` (or, should one
    of its two fixes be an outlier, the step around them)."""
    if _step_speed(t, xy, k, k + 1, p) <= limit:
        return True
    return k > 0 and k + 2 < t.size and _step_speed(t, xy, k - 1, k + 2, p) <= limit


def _refuse(path, order: np.ndarray, t: np.ndarray, xy: np.ndarray, k: int,
            limit: float) -> None:
    a, b = int(order[k]), int(order[k + 1])
    d = float(np.hypot(*(xy[b] - xy[a])))
    raise InconsistentInputError(
        path, f"fix {b + 1} is {t[k] - t[k + 1]:.1f} s earlier than fix {a + 1} before it and "
        f"{d:.0f} m away: neither the time stamps nor the file order make one drive of the "
        f"fixes (each step within {limit:.1f} m/s beyond the noise)",
        "the receiver clock jumps: fix the log's times")


def _names(fixes: list[int]) -> str:
    """'fixes 12, 13 and 40' from 0-based indices (at most 6 named)."""
    n = sorted(int(f) + 1 for f in fixes)
    shown = ", ".join(str(v) for v in n[:6]) + (f" and {len(n) - 6} more" if len(n) > 6 else "")
    return ("fix " if len(n) == 1 else "fixes ") + shown


def _jump_warning(order: np.ndarray, t: np.ndarray, shifted: np.ndarray, k: int,
                  direction: str) -> str:
    """The warning for the fixes after record ``k`` re-timed from ``t`` to ``shifted``."""
    first, last = int(order[k + 1]) + 1, int(order[-1]) + 1
    span = f"fix {first}" if first == last else f"fixes {first}-{last}"
    shift = float(shifted[k + 1] - t[k + 1])
    return (f"the receiver clock jumps {direction} {abs(shift):.1f} s at fix {first} while the "
            f"positions go on in file order: {span} re-timed by {shift:+.1f} s to follow fix "
            f"{int(order[k]) + 1} (the times on one side of the jump are wrong: check the video "
            "sync)")


# --------------------------------------------------------------------------- forward, ties


def _forward_jumps(t: np.ndarray, xy: np.ndarray, order: np.ndarray, p: ClockParams,
                   jumps: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Re-time the fixes after each long time step across which the car cannot have
    stopped: moving at ``v_b`` before and ``v_a`` after, it covers less than
    ``(v_b^2 + v_a^2) / (2 a_max)`` beyond the noise."""
    warnings: list[str] = []
    pos = xy[order]
    for k in np.flatnonzero(np.diff(t) > 2.0).tolist():  # the candidates, then each in turn
        if not 2 <= k < t.size - 3:
            continue
        period = _period(t, k)
        dt = t[k + 1] - t[k]
        if dt <= max(3.0 * period, period + 2.0):
            continue
        v_b = _chord_speed(t, pos, k - 2, k)
        v_a = _chord_speed(t, pos, k + 1, k + 3)
        d = float(np.hypot(*(pos[k + 1] - pos[k])))
        stop_m = (v_b ** 2 + v_a ** 2) / (2.0 * p.max_accel_mps2)
        if min(v_b, v_a) < p.moving_mps or d + p.step_noise_m >= stop_m:
            continue  # a stop fits (or the car was slow): a gap in the fixes, not a jump
        jumps += 1
        if jumps > p.max_jumps:
            raise InconsistentInputError(None, f"the receiver clock jumps more than "
                                         f"{p.max_jumps} times", "no consistent time base")
        shifted = t.copy()
        shifted[k + 1:] -= dt - max(period, d / (0.5 * (v_b + v_a)))
        warnings.append(_jump_warning(order, t, shifted, k, "forward"))
        t = shifted
    return t, order, warnings


def _chord_speed(t: np.ndarray, xy: np.ndarray, a: int, b: int) -> float:
    dt = t[b] - t[a]
    return float(np.hypot(*(xy[b] - xy[a])) / dt) if dt > 0 else 0.0


def _one_fix_per_time(t: np.ndarray, xy: np.ndarray, p: ClockParams
                      ) -> tuple[np.ndarray, dict[int, list[int]]]:
    """Indices (into the time-ordered records) that keep one fix per time stamp: of fixes
    at one place the first; of fixes at different places the one nearest the straight
    line between the fixes before and after, at its time. Also, per kept index, the
    indices dropped for it where the places differed."""
    keep: list[int] = []
    differ: dict[int, list[int]] = {}
    i, n = 0, t.size
    while i < n:
        j = i + 1
        while j < n and t[j] == t[i]:
            j += 1
        group = list(range(i, j))
        spread = max(float(np.hypot(*(xy[g] - xy[i]))) for g in group)
        if len(group) == 1 or spread <= p.step_noise_m:
            keep.append(i)
        else:
            best = min(group, key=lambda g: _miss(t, xy, i - 1, j, g))
            keep.append(best)
            differ[best] = [g for g in group if g != best]
        i = j
    return np.asarray(keep, dtype=np.int64), differ


def _miss(t: np.ndarray, xy: np.ndarray, before: int, after: int, g: int) -> float:
    """How far fix ``g`` lies from where its neighbours in time put the car [m]."""
    if before < 0 and after >= t.size:
        return 0.0
    if before < 0 or after >= t.size:
        ref = xy[after] if before < 0 else xy[before]
    else:
        f = (t[g] - t[before]) / (t[after] - t[before])
        ref = xy[before] + f * (xy[after] - xy[before])
    return float(np.hypot(*(xy[g] - ref)))


def _duplicate_warnings(order: np.ndarray, differ: dict[int, list[int]],
                        keep: np.ndarray) -> list[str]:
    out = []
    for kept, dropped in sorted(differ.items()):
        out.append(f"{_names([int(order[g]) for g in [kept, *dropped]])} carry the same time "
                   f"at different places: kept fix {int(order[kept]) + 1}, the one on the way "
                   "between its neighbours")
    n_same = int(order.size - keep.size - sum(len(v) for v in differ.values()))
    if n_same:
        out.append(f"dropped {n_same} fixes repeating an earlier time")
    return out
