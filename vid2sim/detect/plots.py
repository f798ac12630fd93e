"""Plots of ranged tracks: the lead vehicle over time and a top-down view of all tracks (PNG)."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from vid2sim.base.defaults import LANE_WIDTH_M
from vid2sim.base.fileio import write_bytes_atomic
from vid2sim.core.records import RangedBox


def _figure():
    import matplotlib

    matplotlib.use("Agg")  # files only; never needs a display
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> None:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    write_bytes_atomic(path, buf.getvalue())


def plot_lead(boxes: list[RangedBox], path: str | Path) -> Path:
    """Lead range with a +-2 sigma band and lead range rate over time, one PNG.

    Parameters
    ----------
    boxes : list of RangedBox
        All ranged boxes; only the lead rows are drawn. Frames without a lead leave a gap.
    path : str or Path
        PNG to write (atomically).
    """
    plt = _figure()
    path = Path(path)
    lead = sorted((b for b in boxes if b.is_lead), key=lambda b: b.t_s)
    fig, (ax_r, ax_v) = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
    if lead:
        t = np.array([b.t_s for b in lead])
        r = np.array([b.range_m for b in lead])
        sd = np.array([b.range_std_m for b in lead])
        v = np.array([b.range_rate_mps for b in lead])
        ids = np.array([b.track_id for b in lead])
        # Break the lines where the lead changes or disappears (no line across a cut-in).
        frames = np.array([b.frame for b in lead])
        gaps = np.flatnonzero((np.diff(ids) != 0) | (np.diff(frames) > 1)) + 1
        for seg in np.split(np.arange(len(lead)), gaps):
            ax_r.fill_between(t[seg], r[seg] - 2 * sd[seg], r[seg] + 2 * sd[seg],
                              color="tab:blue", alpha=0.25, linewidth=0)
            ax_r.plot(t[seg], r[seg], color="tab:blue")
            ax_v.plot(t[seg], v[seg], color="tab:red")
        for k in gaps:
            ax_r.axvline(t[k], color="grey", linestyle=":", linewidth=0.8)
        ax_r.set_ylim(bottom=0)
    else:
        ax_r.text(0.5, 0.5, "no lead vehicle", transform=ax_r.transAxes, ha="center")
    ax_v.axhline(0, color="black", linewidth=0.6)
    ax_r.set_ylabel("lead range [m] (band +-2 sigma)")
    ax_v.set_ylabel("lead range rate [m/s]")
    ax_v.set_xlabel("video time [s]")
    ax_r.set_title("Lead vehicle (dotted lines: lead changed)")
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)
    return path


def plot_topdown(boxes: list[RangedBox], path: str | Path, lane_width_m: float = LANE_WIDTH_M) -> Path:
    """Top-down view of every track in the camera's frame (range up, left to the left).

    Each track is one line over time; lead rows are marked; the ego corridor is shaded.
    """
    plt = _figure()
    path = Path(path)
    by_track: dict[int, list[RangedBox]] = defaultdict(list)
    for b in boxes:
        if np.isfinite(b.range_m) and np.isfinite(b.lateral_m):
            by_track[b.track_id].append(b)
    fig, ax = plt.subplots(figsize=(6, 8))
    ax.axvspan(-lane_width_m / 2, lane_width_m / 2, color="0.9", zorder=0, label="ego lane")
    cmap = plt.get_cmap("tab20")
    for k, (tid, rows) in enumerate(sorted(by_track.items())):
        rows.sort(key=lambda b: b.t_s)
        x = [b.lateral_m for b in rows]
        y = [b.range_m for b in rows]
        ax.plot(x, y, color=cmap(k % 20), linewidth=1)
        ax.annotate(str(tid), (x[-1], y[-1]), fontsize=7)
    lead = [b for b in boxes if b.is_lead and np.isfinite(b.range_m)]
    if lead:
        ax.scatter([b.lateral_m for b in lead], [b.range_m for b in lead], s=4, c="black",
                   label="lead", zorder=3)
    ax.plot([0], [0], marker="^", color="tab:green", markersize=10, label="camera")
    # Lateral is positive to the left: invert the axis so the left of the road is on the left.
    ax.invert_xaxis()
    ax.set_xlabel("lateral offset [m], positive to the left")
    ax.set_ylabel("range [m]")
    ax.set_title(f"All tracks, top-down ({len(by_track)} tracks)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_ylim(bottom=-2)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)
    return path
