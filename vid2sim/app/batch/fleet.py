"""The fleet summary page of a batch: ``DIR/fleet.html`` from ``DIR/index.parquet``.

Counts by status and the commonest errors, wall time per build stage, distributions over
the videos of the lead's median range, the smallest time to collision and keyframe F1, and
a per-video table linking each row's ``report.html``. One self-contained HTML file (figures
are base64 PNGs drawn with matplotlib's object API, inline CSS, no scripts), like a row's
report, so it opens offline from any copy of the batch folder.
"""

from __future__ import annotations

import html
import math
from collections import Counter
from datetime import UTC, datetime

import numpy as np

from vid2sim import __version__
from vid2sim.app.batch import storage
from vid2sim.app.batch.index import STATUSES, read_index_records
from vid2sim.app.batch.manifest import FLEET_HTML, INDEX_PARQUET
from vid2sim.app.batch.storage import Where
from vid2sim.base.errors import MissingInputError
from vid2sim.base.htmlpage import BASE_CSS, figure_png, png_base64

#: Rows shown in the per-video table (failed rows first); the full list is index.csv. A
#: 100,000-row table would make a page of tens of MB that browsers render slowly.
TABLE_MAX_ROWS = 1000
#: Commonest error lines listed.
TOP_ERRORS = 10

_CSS = BASE_CSS + """
h2{font-size:17px;margin:0 0 10px}
tr.failed td{background:#fff1f0}
figure{margin:0} figure img{max-width:100%;height:auto;border:1px solid #dde1e8}
"""


def _e(x) -> str:
    return html.escape(str(x))


def _num(v, spec: str = ".2f") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    return format(v, spec)


def _values(records: list[dict], column: str) -> np.ndarray:
    vals = [r.get(column) for r in records if r.get("status") in ("ok", "skipped")]
    out = np.array([float(v) for v in vals if v not in (None, "")], dtype=float)
    return out[np.isfinite(out)]


def _png(fig) -> str:
    return png_base64(figure_png(fig, dpi=100))


def distributions_png(records: list[dict]) -> str:
    """Base64 PNG: histograms over the built videos of lead median range, smallest TTC and
    keyframe F1 (each panel says how many videos have the figure)."""
    panels = (("lead_range_median_m", "lead median range [m]", None),
              ("lead_ttc_min_s", "smallest time to collision [s]", (0.0, 20.0)),
              ("f1", "keyframe F1", (0.0, 1.0)))
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12.0, 3.2))
    for k, (column, label, limits) in enumerate(panels):
        ax = fig.add_subplot(1, 3, k + 1)
        vals = _values(records, column)
        if limits is not None:
            vals = np.clip(vals, *limits)
        if vals.size:
            ax.hist(vals, bins=min(30, max(5, vals.size)), range=limits, color="#3b6fb6",
                    edgecolor="white")
            ax.axvline(float(np.median(vals)), color="#c0392b", lw=1.2,
                       label=f"median {np.median(vals):.2f}")
            ax.legend(fontsize=8)
        else:
            ax.text(0.5, 0.5, "no video has this figure", ha="center", va="center",
                    transform=ax.transAxes, color="#4a5468")
        ax.set_xlabel(label)
        ax.set_ylabel("videos")
        ax.set_title(f"{vals.size} videos", fontsize=9)
    return _png(fig)


def stage_times(records: list[dict]) -> list[tuple[str, int, float, float]]:
    """(stage, videos, total s, median s per video) of every stage column, slowest first."""
    stages = sorted({k for r in records for k in r if k.startswith("stage_")})
    rows = []
    for column in stages:
        vals = np.array([float(r[column]) for r in records if r.get(column) not in (None, "")])
        if vals.size:
            name = column[len("stage_"):-len("_s")].replace("_", " ")
            rows.append((name, int(vals.size), float(vals.sum()), float(np.median(vals))))
    return sorted(rows, key=lambda r: -r[2])


def stage_png(times: list[tuple[str, int, float, float]]) -> str:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 0.45 * len(times) + 1.0))
    ax = fig.add_subplot(1, 1, 1)
    names = [t[0] for t in times][::-1]
    ax.barh(names, [t[2] for t in times][::-1], color="#3b6fb6")
    ax.set_xlabel("total wall time of the videos built [s]")
    return _png(fig)


def render_fleet(records: list[dict], title: str) -> str:
    """The fleet page as HTML text."""
    counts = Counter(r.get("status") or "pending" for r in records)
    done = [r for r in records if r.get("status") in ("ok", "skipped")]
    hours = sum(float(r["duration_s"]) for r in done if r.get("duration_s") not in (None, "")
                ) / 3600.0
    built = [float(r["seconds"]) for r in records
             if r.get("status") == "ok" and r.get("seconds") not in (None, "")]
    kpis = [("videos", len(records)), *[(s, counts.get(s, 0)) for s in STATUSES],
            ("of video built", f"{hours:.2f} h" if hours >= 1.0 else f"{60 * hours:.1f} min")]
    if built:
        kpis.append(("median build [s]", f"{np.median(built):.1f}"))
    parts = [(f"<!doctype html><html><head><meta charset='utf-8'><title>{_e(title)}</title>"
             f"<style>{_CSS}</style></head><body><header><h1>vid2sim fleet summary</h1>"
             f"<p>{_e(title)} &middot; generated {datetime.now(UTC):%Y-%m-%d %H:%M UTC} by "
             f"vid2sim {_e(__version__)} &middot; full table: index.csv / {INDEX_PARQUET}"
             "</p></header><main>")]
    parts.append("<section><h2>Status</h2><div class='kpi'>"
                 + "".join(f"<div><b>{_e(v)}</b>{_e(k)}</div>" for k, v in kpis) + "</div>")
    errors = Counter(r.get("error") for r in records
                     if r.get("status") == "failed" and r.get("error"))
    if errors:
        parts.append("<table><tr><th>rows</th><th class='l'>commonest errors</th></tr>"
                     + "".join(f"<tr><td>{n}</td><td class='l'>{_e(err)}</td></tr>"
                               for err, n in errors.most_common(TOP_ERRORS)) + "</table>")
    parts.append("</section>")
    times = stage_times(records)
    if times:
        total = sum(t[2] for t in times) or 1.0
        parts.append("<section><h2>Time per stage</h2><table><tr><th class='l'>stage</th>"
                     "<th>videos</th><th>total [s]</th><th>median per video [s]</th>"
                     "<th>share</th></tr>"
                     + "".join(f"<tr><td class='l'>{_e(n)}</td><td>{k}</td><td>{s:.1f}</td>"
                               f"<td>{m:.2f}</td><td>{100 * s / total:.0f}%</td></tr>"
                               for n, k, s, m in times)
                     + f"</table><figure><img alt='time per stage' src='data:image/png;base64,"
                       f"{stage_png(times)}'></figure></section>")
    parts.append("<section><h2>Distributions over the videos built</h2><figure><img "
                 "alt='distributions' src='data:image/png;base64,"
                 f"{distributions_png(records)}'><figcaption>Lead: the car ahead in the ego "
                 "lane (median of its range over the video); time to collision: the smallest "
                 "range / closing speed of the lead while it closes faster than 1 m/s "
                 "(values above 20 s drawn at 20); F1: projected simulated boxes against the "
                 "annotated keyframes (IoU &ge; 0.5).</figcaption></figure></section>")
    parts.append(_table_html(records))
    parts.append("</main></body></html>")
    return "".join(parts)


def _table_html(records: list[dict]) -> str:
    ordered = ([r for r in records if r.get("status") == "failed"]
               + [r for r in records if r.get("status") != "failed"])
    shown = ordered[:TABLE_MAX_ROWS]
    columns = (("duration_s", "duration [s]", ".1f"), ("distance_m", "distance [m]", ".0f"),
               ("actors", "actors", "d"), ("lead_share", "lead share", ".2f"),
               ("lead_range_median_m", "lead range median [m]", ".1f"),
               ("lead_closing_speed_max_mps", "max closing [m/s]", ".1f"),
               ("lead_ttc_min_s", "min TTC [s]", ".1f"), ("f1", "F1", ".3f"),
               ("mean_iou", "mean IoU", ".3f"), ("seconds", "build [s]", ".1f"),
               ("peak_rss_mb", "peak RSS [MiB]", ".0f"), ("attempts", "attempts", "d"))
    head = ("<tr><th class='l'>video</th><th class='l'>status</th>"
            + "".join(f"<th>{_e(label)}</th>" for _, label, _ in columns)
            + "<th class='l'>host</th><th class='l'>error</th></tr>")
    body = []
    for r in shown:
        name = _e(r.get("id"))
        link = (f"<a href='{_e(r['report'])}'>{name}</a>" if r.get("report") else name)
        cells = "".join(f"<td>{_num(_typed(r.get(c), spec), spec)}</td>" for c, _, spec in columns)
        status = r.get("status") or "pending"
        body.append(f"<tr class='{_e(status)}'><td class='l'>{link}</td>"
                    f"<td class='l'>{_e(status)}</td>{cells}<td class='l'>{_e(r.get('host') or '')}"
                    f"</td><td class='l'>{_e(r.get('error') or '')}</td></tr>")
    more = (f"<p class='small'>{len(records) - len(shown)} more rows in index.csv.</p>"
            if len(records) > len(shown) else "")
    return (f"<section><h2>Videos</h2><table>{head}{''.join(body)}</table>{more}</section>")


def _typed(v, spec: str):
    if v in (None, ""):
        return None
    try:
        return int(float(v)) if spec == "d" else float(v)
    except (TypeError, ValueError):
        return None


def write_fleet_report(out_dir: str | Where, path: str | Where | None = None) -> Where:
    """Write the fleet page of the batch in ``out_dir`` (default ``out_dir/fleet.html``).

    Raises :class:`InputError` when ``out_dir`` holds no batch index.
    """
    out = storage.location(out_dir)
    records = read_index_records(out)
    if not records:
        raise MissingInputError(out, "no batch index here (index.parquet or index.csv)",
                                "give the --out folder of a `vid2sim batch` run")
    target = storage.location(path) if path is not None else storage.join(out, FLEET_HTML)
    storage.write_bytes(target, render_fleet(records, str(out)).encode("utf-8"))
    return target
