"""Range errors by range bin: signed bias and median absolute error, absolute and relative.

One table for every real-data check of ranging (lidar cuboids, KITTI labels, composite
clips), so that figures by regime are read the same way everywhere: a bias that a median
|error| hides (every box 20 % long) shows as the signed median.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: The range bins of the real-box checks [m] (issue 13): near leads, city following distances,
#: the bulk of a street scene, and far traffic.
RANGE_BINS_M: tuple[tuple[float, float], ...] = ((0.0, 10.0), (10.0, 20.0), (20.0, 40.0),
                                                 (40.0, math.inf))


@dataclass(frozen=True)
class BinFigures:
    """Errors of the estimates whose true range falls in one bin.

    ``bias_rel`` and ``bias_m``: median signed error (estimate - truth), relative and [m];
    ``med_abs_rel`` and ``med_abs_m``: median |error|; ``p90_abs_rel``: 90th percentile of
    |relative error|.
    """

    label: str
    n: int
    bias_rel: float
    med_abs_rel: float
    p90_abs_rel: float
    bias_m: float
    med_abs_m: float


def _figures(label: str, truth: np.ndarray, est: np.ndarray) -> BinFigures:
    if truth.size == 0:
        return BinFigures(label, 0, math.nan, math.nan, math.nan, math.nan, math.nan)
    err = est - truth
    rel = err / truth
    return BinFigures(label, int(truth.size), float(np.median(rel)),
                      float(np.median(np.abs(rel))), float(np.percentile(np.abs(rel), 90)),
                      float(np.median(err)), float(np.median(np.abs(err))))


def bin_label(lo: float, hi: float) -> str:
    """"< 10 m", "10-20 m", "> 40 m"."""
    if lo <= 0:
        return f"< {hi:g} m"
    if math.isinf(hi):
        return f"> {lo:g} m"
    return f"{lo:g}-{hi:g} m"


def bin_figures(truth_m: np.ndarray, est_m: np.ndarray,
                bins: tuple[tuple[float, float], ...] = RANGE_BINS_M) -> list[BinFigures]:
    """Figures per bin of the TRUE range, then over all (rows with a non-finite estimate or
    truth are left out and counted by neither)."""
    t = np.asarray(truth_m, dtype=float)
    e = np.asarray(est_m, dtype=float)
    ok = np.isfinite(t) & np.isfinite(e) & (t > 0)
    t, e = t[ok], e[ok]
    out = [_figures(bin_label(lo, hi), t[(t >= lo) & (t < hi)], e[(t >= lo) & (t < hi)])
           for lo, hi in bins]
    out.append(_figures("all", t, e))
    return out


def format_bin_table(title: str, rows: list[BinFigures]) -> str:
    """A markdown table of :func:`bin_figures` under a title line."""
    lines = [title, "",
             "| true range | n | bias (median signed) | median abs error | p90 abs error |",
             "| --- | ---: | ---: | ---: | ---: |"]
    for r in rows:
        if r.n == 0:
            lines.append(f"| {r.label} | 0 | - | - | - |")
            continue
        lines.append(f"| {r.label} | {r.n} | {100 * r.bias_rel:+.1f} % ({r.bias_m:+.2f} m) | "
                     f"{100 * r.med_abs_rel:.1f} % ({r.med_abs_m:.2f} m) | "
                     f"{100 * r.p90_abs_rel:.1f} % |")
    return "\n".join(lines)
