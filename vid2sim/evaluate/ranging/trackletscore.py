"""Ranged boxes scored against KITTI raw tracklets: range by true-range bin, range rate,
lateral offset, split by parked/moving and by a bottom edge cut by the image border.

Every ranged box (a ``tracks.csv`` row) is matched one-to-one, per frame, to the projected
tracklet hull it overlaps most (IoU >= 0.5; the hull is only the association: a cuboid's
hull is not what a detector's box hugs). The truth is the tracklet's 3D box
(:mod:`vid2sim.evaluate.ranging.tracklets`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vid2sim.core.records import RangedBox
from vid2sim.evaluate.metrics import match_boxes
from vid2sim.evaluate.ranging.table import RANGE_BINS_M, bin_figures, bin_label
from vid2sim.evaluate.ranging.tracklets import TrackletTruth

#: A ranged box is the tracklet whose projected hull it overlaps by at least this.
MATCH_IOU = 0.5
#: A tracklet hull this far inside both side borders [px] has its side edges in view: its
#: box's bottom may be cut while its width is whole (the near lead's regime), unlike a car
#: leaving the image at the side, whose box a detector stops short of the border.
SIDES_IN_VIEW_PX = 40.0


@dataclass
class TrackletRows:
    """Matched (ranged box, tracklet) pairs as columns; ``*_true`` from the tracklet."""

    frame: np.ndarray
    track_id: np.ndarray
    object_id: np.ndarray
    object_type: np.ndarray
    iou: np.ndarray
    range_true: np.ndarray
    range_est: np.ndarray
    rate_true: np.ndarray
    rate_est: np.ndarray
    lateral_true: np.ndarray
    lateral_est: np.ndarray
    ground_true: np.ndarray
    parked: np.ndarray
    bottom_cut: np.ndarray
    side_margin_px: np.ndarray

    def __len__(self) -> int:
        return len(self.frame)

    def subset(self, mask: np.ndarray) -> TrackletRows:
        return TrackletRows(*(getattr(self, k)[mask] for k in self.__dataclass_fields__))


def match_tracklets(boxes: Sequence[RangedBox], truth: TrackletTruth,
                    min_iou: float = MATCH_IOU) -> TrackletRows:
    """Each frame's ranged boxes matched one-to-one to the tracklets in view there."""
    by_frame: dict[int, list[RangedBox]] = {}
    for b in boxes:
        by_frame.setdefault(int(b.frame), []).append(b)
    pairs: list[tuple[RangedBox, int, float]] = []
    for f in sorted(by_frame):
        bs = by_frame[f]
        ti = truth.at_frame(f)
        ti = ti[np.isfinite(truth.box_px[ti, 0])]
        if not ti.size:
            continue
        det = [(b.x1, b.y1, b.x2, b.y2) for b in bs]
        pairs += [(bs[i], int(ti[j]), iou)
                  for i, j, iou in match_boxes(det, truth.box_px[ti], min_iou=min_iou)]
    j = np.array([p[1] for p in pairs], dtype=int)

    def est(name: str) -> np.ndarray:
        return np.array([getattr(p[0], name) for p in pairs], dtype=float)

    return TrackletRows(
        frame=truth.frame[j], track_id=np.array([p[0].track_id for p in pairs], dtype=int),
        object_id=truth.object_id[j], object_type=truth.object_type[j],
        iou=np.array([p[2] for p in pairs]), range_true=truth.range_m[j],
        range_est=est("range_m"), rate_true=truth.range_rate_mps[j],
        rate_est=est("range_rate_mps"), lateral_true=truth.lateral_m[j],
        lateral_est=est("lateral_m"), ground_true=truth.ground_z_m[j], parked=truth.parked[j],
        bottom_cut=truth.bottom_cut[j], side_margin_px=truth.side_margin_px[j])


@dataclass(frozen=True)
class RateFigures:
    """Range-rate error (estimate - truth) [m/s] of a group of rows with both known."""

    n: int
    rmse: float
    bias: float
    med_abs: float


def rate_figures(rows: TrackletRows) -> RateFigures:
    ok = np.isfinite(rows.rate_true) & np.isfinite(rows.rate_est)
    e = rows.rate_est[ok] - rows.rate_true[ok]
    if not e.size:
        return RateFigures(0, math.nan, math.nan, math.nan)
    return RateFigures(int(e.size), float(np.sqrt(np.mean(e ** 2))), float(np.median(e)),
                       float(np.median(np.abs(e))))


def lateral_figures(rows: TrackletRows) -> tuple[int, float, float]:
    """(n, median signed, median |error|) of the lateral offset [m]."""
    ok = np.isfinite(rows.lateral_true) & np.isfinite(rows.lateral_est)
    e = rows.lateral_est[ok] - rows.lateral_true[ok]
    if not e.size:
        return 0, math.nan, math.nan
    return int(e.size), float(np.median(e)), float(np.median(np.abs(e)))


def groups(rows: TrackletRows) -> dict[str, TrackletRows]:
    """The rows split the ways the report reads them: all, parked/moving, bottom cut/not."""
    sides = rows.side_margin_px >= SIDES_IN_VIEW_PX
    return {"all": rows, "parked": rows.subset(rows.parked),
            "moving": rows.subset(~rows.parked),
            "bottom cut by the border": rows.subset(rows.bottom_cut),
            "bottom cut, sides in view": rows.subset(rows.bottom_cut & sides),
            "bottom in view": rows.subset(~rows.bottom_cut)}


def _pct(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{100 * x:+.1f} %"


def range_table(rows: TrackletRows) -> list[str]:
    """Markdown rows: per true-range bin, per group: n, signed median, median |error|."""
    lines = ["| group | true range | n | signed median | median abs |",
             "| --- | --- | ---: | ---: | ---: |"]
    for name, g in groups(rows).items():
        for b in bin_figures(g.range_true, g.range_est, RANGE_BINS_M):
            if b.n == 0:
                continue
            lines.append(f"| {name} | {b.label} | {b.n} | {_pct(b.bias_rel)} | "
                         f"{100 * b.med_abs_rel:.1f} % |")
    return lines


def rate_table(rows: TrackletRows) -> list[str]:
    """Markdown rows: range rate per group and per true-range bin: n, RMSE, median bias."""
    lines = [("| group | true range | n | rate RMSE [m/s] | median bias [m/s] | "
              "median abs [m/s] |"), "| --- | --- | ---: | ---: | ---: | ---: |"]
    for name, g in groups(rows).items():
        bins = [("all", np.ones(len(g), bool))] + [
            (bin_label(lo, hi), (g.range_true >= lo) & (g.range_true < hi))
            for lo, hi in RANGE_BINS_M]
        for label, m in bins:
            r = rate_figures(g.subset(m))
            if r.n:
                lines.append(f"| {name} | {label} | {r.n} | {r.rmse:.2f} | {r.bias:+.2f} | "
                             f"{r.med_abs:.2f} |")
    return lines


def lateral_table(rows: TrackletRows) -> list[str]:
    lines = ["| group | n | lateral signed median [m] | lateral median abs [m] |",
             "| --- | ---: | ---: | ---: |"]
    for name, g in groups(rows).items():
        n, bias, mad = lateral_figures(g)
        if n:
            lines.append(f"| {name} | {n} | {bias:+.2f} | {mad:.2f} |")
    return lines


def format_tracklet_report(rows: TrackletRows, title: str) -> str:
    """The three tables (range, range rate, lateral) under a title."""
    types = dict(zip(*np.unique(rows.object_type.astype(str), return_counts=True),
                     strict=True))
    head = (f"{title}: {len(rows)} boxes matched (IoU >= {MATCH_IOU:g}) "
            f"({', '.join(f'{k} {v}' for k, v in sorted(types.items()))})")
    return "\n".join([head, "", "Range (estimate - truth) / truth:", "", *range_table(rows),
                      "", "Range rate (estimate - truth):", "", *rate_table(rows), "",
                      "Lateral offset (estimate - truth):", "", *lateral_table(rows)])
