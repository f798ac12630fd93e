"""summary.html of a ``test-policy`` campaign: the campaign table, heat maps over the varied
parameters, gap/TTC/speed over time per scenario, every episode, and what the metrics mean.

One self-contained file (images base64-embedded PNGs, inline CSS, no scripts), as the build
report. Figures use matplotlib's object API (no pyplot state).
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure

from vid2sim import __version__
from vid2sim.adas.episode_metrics import COLUMNS as METRIC_COLUMNS
from vid2sim.adas.registry import describe
from vid2sim.adas.variations import PARAMETERS, label
from vid2sim.base.fileio import write_text_atomic
from vid2sim.base.htmlpage import BASE_CSS, figure_png, png_base64

TTC_PLOT_MAX_S = 10.0
"""TTC above this is drawn at the top of the plots [s] (beyond it nothing is urgent)."""
HEAT_TTC_MAX_S = 5.0
"""Colour scale of the minimum-TTC heat map [s]: red at 0, green from this value on."""
MAX_TABLE_ROWS = 500

_CSS = BASE_CSS + """
h2{font-size:17px;margin:0 0 10px} h3{font-size:14px;margin:12px 0 6px}
tr.bad td{background:#fde8e8} tr.skip td{color:#8a93a6}
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(520px,1fr));gap:12px}
.wide{display:grid;grid-template-columns:repeat(auto-fill,minmax(860px,1fr));gap:12px}
.scroll{overflow-x:auto}
figure{margin:0;min-width:0}
figure img{width:100%;height:auto;border:1px solid #dde1e8;display:block}
dt{font-weight:600;margin-top:6px} dd{margin:2px 0 0 18px;font-size:13px}
"""

_METRIC_TEXT = {
    "collision": "the ego's box touched another vehicle's (1) or not (0).",
    "min_ttc_s": "smallest time to collision with the lead: bumper gap / closing speed [s]; "
                 "inf when never closing. Below about 1.5 s is critical.",
    "min_headway_s": "smallest time headway to the lead: gap / own speed [s]; inf without a "
                     "lead. Following below 1 s is close, below 0.5 s tailgating.",
    "min_gap_m": "smallest bumper-to-bumper gap to the lead along the ego's path [m]; inf "
                 "without a lead, negative when the boxes overlapped.",
    "max_decel_mps2": "largest deceleration over a 0.1 s step [m/s^2]: 3-4 is firm braking, "
                      "8 full braking.",
    "max_jerk_mps3": "largest change of acceleration per second [m/s^3]: comfort ends near 2-3; "
                     "an emergency brake's onset is a step (tens).",
    "lane_departures": "times the ego's body crossed a marking of its map lane (a lane change "
                       "counts once).",
    "duration_s": "simulated time [s]; shorter than the scenario when a collision or leaving "
                  "the road ended the episode.",
    "score": "one figure per episode in [0, 1], shaped like nuPlan's closed-loop score: 0 on "
             "an at-fault collision, leaving the road, driving against the lane or making no "
             "progress; else the weighted average of TTC >= 0.95 s (5), progress along the "
             "recorded route (5), speed-limit compliance where the map has a limit (4) and "
             "comfort (2). Its terms are results.csv's score_* columns.",
}


def _png(fig: Figure) -> str:
    return "data:image/png;base64," + png_base64(figure_png(fig, dpi=100, tight=False))


def _fmt(value, digits: int = 2) -> str:
    if value is None:
        return ""
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if math.isinf(value):
        return "inf"
    return f"{value:.{digits}f}"


# --------------------------------------------------------------------------- figures


def time_figure(entry, episodes) -> str:
    """Gap, TTC and ego speed over time: every episode thin, the recorded log dashed, the
    episode with the smallest TTC red."""
    fig = Figure(figsize=(8.0, 6.4))
    ax_gap, ax_ttc, ax_v = fig.subplots(3, 1, sharex=True)
    run = [ep for ep in episodes if ep.result is not None and ep.result.metrics is not None]
    worst = min(run, key=lambda ep: (ep.result.metrics.min_ttc_s, ep.result.metrics.min_gap_m),
                default=None)
    for ep in run:
        s = ep.result.series
        is_worst = ep is worst
        kw = {"color": "#c0392b" if is_worst else "#3b6fb6", "lw": 1.6 if is_worst else 0.7,
              "alpha": 1.0 if is_worst else 0.35, "zorder": 3 if is_worst else 2}
        ax_gap.plot(s["t_s"], s["gap_m"], **kw)
        ax_ttc.plot(s["t_s"], np.minimum(s["ttc_s"], TTC_PLOT_MAX_S), **kw)
        ax_v.plot(s["t_s"], s["ego_speed_mps"], **kw,
                  label=("smallest TTC: " + label(ep.values)) if is_worst else None)
    if entry.recorded is not None:
        s = entry.recorded.series
        kw = {"color": "black", "lw": 1.0, "ls": "--", "zorder": 4}
        ax_gap.plot(s["t_s"], s["gap_m"], **kw)
        ax_ttc.plot(s["t_s"], np.minimum(s["ttc_s"], TTC_PLOT_MAX_S), **kw)
        ax_v.plot(s["t_s"], s["ego_speed_mps"], **kw, label="recorded ego (log)")
        ax_v.plot(s["t_s"], s["lead_speed_mps"], color="grey", lw=0.8, ls=":",
                  label="recorded lead speed")
    ax_gap.set_ylabel("gap to lead [m]")
    ax_ttc.set_ylabel(f"TTC [s] (cut at {TTC_PLOT_MAX_S:g})")
    ax_ttc.axhline(1.5, color="#c0392b", lw=0.6, ls=":")
    ax_v.set_ylabel("ego speed [m/s]")
    ax_v.set_xlabel("scenario time [s]")
    for ax in (ax_gap, ax_ttc, ax_v):
        ax.grid(alpha=0.3)
    ax_v.legend(fontsize=8, loc="best")
    fig.suptitle(entry.name, fontsize=10)
    fig.tight_layout()
    return _png(fig)


def _varied_axes(axes) -> list:
    return [a for a in axes if a.values is None or len(a.values) > 1]


def heat_figure(entry, episodes, axes) -> str | None:
    """Collision and minimum TTC over the first two varied parameters (a grid: cells, other
    parameters folded by worst case; random samples: points), or over one."""
    varied = _varied_axes(axes)
    if not varied:
        return None
    done = [ep for ep in episodes if ep.result is not None]
    fig = Figure(figsize=(10.0, 4.2))
    ax_c, ax_t = fig.subplots(1, 2)
    ttc_cmap = matplotlib.colormaps["RdYlGn"]
    if len(varied) == 1 or any(a.values is None for a in varied[:2]):
        return _scatter(fig, ax_c, ax_t, entry, done, varied)
    xa, ya = varied[0], varied[1]
    xs, ys = list(xa.values), list(ya.values)
    coll = np.full((len(ys), len(xs)), np.nan)
    ttc = np.full((len(ys), len(xs)), np.nan)
    for ep in done:
        i, j = ys.index(ep.values[ya.name]), xs.index(ep.values[xa.name])
        if ep.result.metrics is None:
            continue
        m = ep.result.metrics
        coll[i, j] = max(np.nan_to_num(coll[i, j], nan=0.0), float(m.collision))
        ttc[i, j] = np.fmin(ttc[i, j], min(m.min_ttc_s, HEAT_TTC_MAX_S))
    cmap_c = ListedColormap(["#2e8b57", "#c0392b"])
    for ax, data, cmap, vmax, title in (
            (ax_c, coll, cmap_c, 1.0, "collision (red) / none (green); grey: skipped"),
            (ax_t, ttc, ttc_cmap, HEAT_TTC_MAX_S, (f"minimum TTC [s] (>= {HEAT_TTC_MAX_S:g} "
             "green)"))):
        cm = cmap.with_extremes(bad="#c8ccd4")
        im = ax.imshow(np.ma.masked_invalid(data), origin="lower", cmap=cm, vmin=0.0,
                       vmax=vmax, aspect="auto")
        ax.set_xticks(range(len(xs)), [f"{v:.3g}" for v in xs])
        ax.set_yticks(range(len(ys)), [f"{v:.3g}" for v in ys])
        ax.set_xlabel(f"{xa.name}: {PARAMETERS[xa.name][0]}")
        ax.set_ylabel(f"{ya.name}: {PARAMETERS[ya.name][0]}")
        ax.set_title(title, fontsize=9)
        for i in range(len(ys)):
            for j in range(len(xs)):
                if ax is ax_t and np.isfinite(ttc[i, j]):
                    text = f"{ttc[i, j]:.1f}" + ("+" if ttc[i, j] >= HEAT_TTC_MAX_S else "")
                    ax.text(j, i, text, ha="center", va="center", fontsize=8)
                elif ax is ax_c and coll[i, j] == 1.0:
                    ax.text(j, i, "X", ha="center", va="center", color="white", fontsize=10)
        if ax is ax_t:
            fig.colorbar(im, ax=ax, fraction=0.046)
    fig.suptitle(entry.name, fontsize=10)
    fig.tight_layout()
    return _png(fig)


def score_heat_figure(entry, episodes, axes) -> str | None:
    """The episode score over the first two varied parameters of a grid (lowest over any
    others), or over the first one (points); None without a varied parameter or a score."""
    varied = _varied_axes(axes)
    scored = [ep for ep in episodes if ep.result is not None and ep.result.score is not None]
    if not varied or not scored:
        return None
    fig = Figure(figsize=(5.4, 4.2))
    ax = fig.subplots()
    cmap = matplotlib.colormaps["RdYlGn"].with_extremes(bad="#c8ccd4")
    xa = varied[0]
    if len(varied) > 1 and all(a.values is not None for a in varied[:2]):
        ya = varied[1]
        xs, ys = list(xa.values), list(ya.values)
        grid = np.full((len(ys), len(xs)), np.nan)
        for ep in scored:
            i, j = ys.index(ep.values[ya.name]), xs.index(ep.values[xa.name])
            grid[i, j] = np.fmin(grid[i, j], ep.result.score.score)
        im = ax.imshow(np.ma.masked_invalid(grid), origin="lower", cmap=cmap, vmin=0.0,
                       vmax=1.0, aspect="auto")
        ax.set_xticks(range(len(xs)), [f"{v:.3g}" for v in xs])
        ax.set_yticks(range(len(ys)), [f"{v:.3g}" for v in ys])
        ax.set_ylabel(f"{ya.name}: {PARAMETERS[ya.name][0]}")
        for i, j in zip(*np.nonzero(np.isfinite(grid)), strict=True):
            ax.text(j, i, f"{grid[i, j]:.2f}", ha="center", va="center", fontsize=8)
    else:
        x = [ep.values[xa.name] for ep in scored]
        y = [ep.result.score.score for ep in scored]
        im = ax.scatter(x, y, c=y, cmap=cmap, vmin=0.0, vmax=1.0, s=30)
        ax.set_ylabel("score")
        ax.set_ylim(-0.05, 1.05)
        ax.grid(alpha=0.3)
    ax.set_xlabel(f"{xa.name}: {PARAMETERS[xa.name][0]}")
    ax.set_title("episode score (0 red, 1 green)", fontsize=9)
    fig.colorbar(im, ax=ax, fraction=0.046)
    fig.suptitle(entry.name, fontsize=10)
    fig.tight_layout()
    return _png(fig)


def _scatter(fig, ax_c, ax_t, entry, done, varied) -> str:
    xa = varied[0]
    ya = varied[1] if len(varied) > 1 else None
    run = [ep for ep in done if ep.result.metrics is not None]
    skipped = [ep for ep in done if ep.result.metrics is None]
    x = np.array([ep.values[xa.name] for ep in run])
    y = (np.array([ep.values[ya.name] for ep in run]) if ya else
         np.array([min(ep.result.metrics.min_ttc_s, HEAT_TTC_MAX_S) for ep in run]))
    coll = np.array([ep.result.metrics.collision for ep in run], bool)
    ttc = np.array([min(ep.result.metrics.min_ttc_s, HEAT_TTC_MAX_S) for ep in run])
    ax_c.scatter(x[~coll], y[~coll], c="#2e8b57", s=28, label="no collision")
    ax_c.scatter(x[coll], y[coll], c="#c0392b", marker="x", s=40, label="collision")
    if skipped:
        sx = [ep.values[xa.name] for ep in skipped]
        sy = [ep.values[ya.name] if ya else 0.0 for ep in skipped]
        ax_c.scatter(sx, sy, c="#8a93a6", marker=".", s=20, label="skipped")
    ax_c.legend(fontsize=8)
    sc = ax_t.scatter(x, y, c=ttc, cmap="RdYlGn", vmin=0.0, vmax=HEAT_TTC_MAX_S, s=30)
    fig.colorbar(sc, ax=ax_t, fraction=0.046, label="minimum TTC [s]")
    for ax in (ax_c, ax_t):
        ax.set_xlabel(f"{xa.name}: {PARAMETERS[xa.name][0]}")
        ax.set_ylabel(f"{ya.name}: {PARAMETERS[ya.name][0]}" if ya else "minimum TTC [s]")
        ax.grid(alpha=0.3)
    ax_c.set_title("collision", fontsize=9)
    ax_t.set_title("minimum TTC [s]", fontsize=9)
    fig.suptitle(entry.name, fontsize=10)
    fig.tight_layout()
    return _png(fig)


# --------------------------------------------------------------------------- page


def _scenario_rows(entries, episodes) -> str:
    rows = []
    for si, entry in enumerate(entries):
        mine = [ep for ep in episodes if ep.scenario_index == si]
        run = [ep.result.metrics for ep in mine if ep.result and ep.result.metrics]
        hand = sum(len(ep.result.handovers) for ep in mine if ep.result and ep.result.metrics)
        rec = entry.recorded.metrics if entry.recorded is not None else None
        cells = [len(mine), len(run), len(mine) - len(run), sum(m.collision for m in run),
                 min((m.min_ttc_s for m in run), default=None),
                 min((m.min_headway_s for m in run), default=None),
                 min((m.min_gap_m for m in run), default=None),
                 max((m.max_decel_mps2 for m in run), default=None),
                 max((m.max_jerk_mps3 for m in run), default=None),
                 sum(m.lane_departures for m in run), hand,
                 rec.min_gap_m if rec else None, rec.min_ttc_s if rec else None]
        bad = any(m.collision for m in run)
        rows.append(f"<tr class='{'bad' if bad else ''}'><td class='l'>{html.escape(entry.name)}"
                    "</td>" + "".join(f"<td>{_fmt(c)}</td>" for c in cells) + "</tr>")
    head = ("<tr><th class='l'>scenario</th><th>episodes</th><th>run</th><th>skipped</th>"
            "<th>collisions</th><th>min TTC [s]</th><th>min headway [s]</th><th>min gap [m]"
            "</th><th>max decel [m/s²]</th><th>max jerk [m/s³]</th><th>lane departures</th>"
            "<th>handovers</th><th>recorded min gap [m]</th><th>recorded min TTC [s]</th></tr>")
    return f"<div class='scroll'><table>{head}{''.join(rows)}</table></div>"


def _episode_rows(entries, spec, episodes) -> str:
    head = ("<tr><th class='l'>scenario</th><th class='l'>variation</th>"
            + "".join(f"<th>{c}</th>" for c in METRIC_COLUMNS)
            + "<th>score</th><th>handovers</th><th class='l'>AEB</th><th class='l'>note</th>"
            "</tr>")
    rows = []
    for ep in episodes[:MAX_TABLE_ROWS]:
        r = ep.result
        name = html.escape(entries[ep.scenario_index].name)
        var = html.escape(label(ep.values))
        if r is None or r.metrics is None:
            note = html.escape(r.skip_reason if r else "")
            rows.append(f"<tr class='skip'><td class='l'>{name}</td><td class='l'>{var}</td>"
                        + "<td></td>" * (len(METRIC_COLUMNS) + 3)
                        + f"<td class='l'>skipped: {note}</td></tr>")
            continue
        m = r.metrics.as_dict()
        hand = "; ".join(f"{h.actor_id} at {h.t_s:.1f} s ({h.reason})" for h in r.handovers)
        aeb = ", ".join(f"{n} {t:.1f} s" for t, n in r.events)
        rows.append(f"<tr class='{'bad' if m['collision'] else ''}'><td class='l'>{name}</td>"
                    f"<td class='l'>{var}</td>"
                    + "".join(f"<td>{_fmt(m[c])}</td>" for c in METRIC_COLUMNS)
                    + f"<td>{_fmt(r.score.score if r.score else None)}</td>"
                    + f"<td class='l'>{html.escape(hand)}</td><td class='l'>"
                    f"{html.escape(aeb)}</td><td class='l'>{html.escape(r.terminated_by)}</td>"
                    "</tr>")
    more = (f"<p class='small'>First {MAX_TABLE_ROWS} of {len(episodes)} episodes; all are in "
            "results.csv.</p>" if len(episodes) > MAX_TABLE_ROWS else "")
    return f"<div class='scroll'><table>{head}{''.join(rows)}</table></div>{more}"


def _videos_html(entries, episodes, videos: dict[int, str]) -> str:
    """The episode videos (``test-policy --render``), each with what happened in it."""
    items = []
    for k, href in sorted(videos.items()):
        ep = episodes[k]
        m = ep.result.metrics
        what = (f"episode {k}: {entries[ep.scenario_index].name}, {label(ep.values)}; "
                + (f"collision at {ep.result.collision_t_s:.1f} s"
                   if ep.result.collision_t_s is not None else
                   f"no collision, min TTC {_fmt(m.min_ttc_s)} s, min gap {_fmt(m.min_gap_m)} m"))
        items.append(f"<figure><video controls preload='metadata' src='{html.escape(href)}' "
                     f"style='width:100%;height:auto;background:#000'></video><figcaption>"
                     f"{html.escape(what)} (<a href='{html.escape(href)}'>{html.escape(href)}"
                     "</a>)</figcaption></figure>")
    return ("<section><h2>Episode videos: the policy's drive from above, the recorded ego as "
            "a white outline, gap, speeds and TTC below, AEB stages and the collision "
            "marked</h2><div class='grid'>" + "".join(items) + "</div></section>")


def render_summary(*, entries, spec, episodes, axes, options, videos=None) -> str:
    """The page's HTML (``videos``: episode index -> episode video, relative to the page)."""
    run = [ep.result.metrics for ep in episodes if ep.result and ep.result.metrics]
    collisions = sum(m.collision for m in run)
    kpis = [("episodes", len(episodes)), ("run", len(run)), ("skipped", len(episodes) - len(run)),
            ("with a collision", collisions),
            ("smallest TTC [s]", _fmt(min((m.min_ttc_s for m in run), default=None))),
            ("smallest gap [m]", _fmt(min((m.min_gap_m for m in run), default=None)))]
    opts = [("policy", describe(spec)), ("reactive replay", "on" if options.reactive else "off"),
            ("sensor noise level", f"{options.sensor_noise:g}" + (" (exact)" if
                                                                   not options.sensor_noise
                                                                   else "")),
            ("--vary", options.vary or "none"), ("--samples", options.samples or "grid / one"),
            ("--seed", options.seed)]
    parts = [(f"<header><h1>Policy test: {html.escape(describe(spec))}</h1><p>vid2sim "
             f"{__version__} &middot; {len(entries)} scenario(s)</p></header><main>"),
             "<section><h2>Campaign</h2><div class='kpi'>"
             + "".join(f"<div><b>{html.escape(str(v))}</b>{html.escape(k)}</div>"
                       for k, v in kpis) + "</div>"
             + "<table>" + "".join(f"<tr><th class='l'>{html.escape(k)}</th><td class='l'>"
                                   f"{html.escape(str(v))}</td></tr>" for k, v in opts)
             + "</table>" + _scenario_rows(entries, episodes) + "</section>"]
    heat = []
    for si, entry in enumerate(entries):
        img = heat_figure(entry, [ep for ep in episodes if ep.scenario_index == si], axes)
        if img:
            heat.append(f"<figure><img alt='heat map {html.escape(entry.name)}' src='{img}'>"
                        f"<figcaption>{html.escape(entry.name)}: collision and minimum TTC over "
                        "the varied parameters (worst case over any others)</figcaption>"
                        "</figure>")
        img = score_heat_figure(entry, [ep for ep in episodes if ep.scenario_index == si], axes)
        if img:
            heat.append(f"<figure><img alt='score {html.escape(entry.name)}' src='{img}'>"
                        f"<figcaption>{html.escape(entry.name)}: the episode score over the "
                        "varied parameters (lowest over any others)</figcaption></figure>")
    if heat:
        parts.append("<section><h2>Variations</h2><div class='wide'>" + "".join(heat)
                     + "</div></section>")
    plots = []
    for si, entry in enumerate(entries):
        img = time_figure(entry, [ep for ep in episodes if ep.scenario_index == si])
        plots.append(f"<figure><img alt='time plots {html.escape(entry.name)}' src='{img}'>"
                     f"<figcaption>{html.escape(entry.name)}: every episode (blue), the smallest "
                     "TTC (red), the recorded log (dashed)</figcaption></figure>")
    parts.append("<section><h2>Gap, TTC and speed over time</h2><div class='grid'>"
                 + "".join(plots) + "</div></section>")
    if videos:
        parts.append(_videos_html(entries, episodes, videos))
    parts.append("<section><h2>Episodes</h2>" + _episode_rows(entries, spec, episodes)
                 + "</section>")
    parts.append("<section><h2>What the figures mean</h2><dl>"
                 + "".join(f"<dt>{k}</dt><dd>{html.escape(v)}</dd>"
                           for k, v in _METRIC_TEXT.items())
                 + "<dt>handovers</dt><dd>recorded actors that left their log for IDM/MOBIL "
                 "(reactive replay), with when and why.</dd></dl></section></main>")
    return ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>vid2sim policy "
            f"test</title><style>{_CSS}</style></head><body>{''.join(parts)}</body></html>\n")


def write_summary(path: Path, **kwargs) -> None:
    """Write summary.html atomically (see :func:`render_summary` for the arguments)."""
    write_text_atomic(path, render_summary(**kwargs))
