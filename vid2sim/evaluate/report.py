"""The self-contained HTML report: inputs, map, lead plots, keyframes, metrics, warnings.

One file, images base64-embedded, inline CSS, no scripts and no external resources, so it
opens in any browser, offline, and can be mailed as is. Figures are drawn with matplotlib's
object API (no pyplot global state) from the scenario itself.
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import matplotlib
import numpy as np
from matplotlib.figure import Figure

from vid2sim import __version__
from vid2sim.base.defaults import LANE_WIDTH_M
from vid2sim.base.errors import FormatError, MissingInputError
from vid2sim.base.fileio import write_text_atomic
from vid2sim.base.htmlpage import BASE_CSS, figure_png
from vid2sim.core.scenario import Scenario
from vid2sim.evaluate.scenetime import SceneClock

LEAD_SAMPLE_HZ = 10.0
"""Rate at which the lead vehicle is looked up for the plots [Hz]."""

ImageLike = bytes | str | Path

_CSS = BASE_CSS + """
h2{font-size:17px;margin:0 0 10px}
.warn{background:#fff6e0;border-color:#f0c36d}
.warn li{margin:3px 0}
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(380px,1fr));gap:12px}
figure{margin:0;min-width:0}
figure img{width:100%;height:auto;border:1px solid #dde1e8;display:block}
code,pre{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:12px}
pre{background:#f3f4f7;padding:8px;overflow-x:auto;white-space:pre-wrap}
.frames{display:grid;grid-template-columns:1fr;gap:14px}
"""


# --------------------------------------------------------------------------- figures


def _png(fig: Figure) -> bytes:
    return figure_png(fig, dpi=110)


def map_figure(scenario: Scenario) -> bytes:
    """PNG of the roads' centerlines, the ego path and every actor's path (ENU metres)."""
    fig = Figure(figsize=(7.5, 6.0))
    ax = fig.add_subplot(1, 1, 1)
    for i, road in enumerate(scenario.roads):
        line = road.centerline
        width_pt = max(2.0, road.lanes * 2.5)
        ax.plot(line[:, 0], line[:, 1], color="#b8bec9", lw=width_pt, solid_capstyle="round",
                label="road centerline" if i == 0 else None, zorder=1)
    ego = scenario.ego.trajectory
    ax.plot(ego.x, ego.y, color="#1f5fbf", lw=2.2, label="ego", zorder=3)
    ax.plot(ego.x[:1], ego.y[:1], "o", color="#1f5fbf", ms=6, zorder=4)
    cmap = matplotlib.colormaps["tab10"]
    for k, actor in enumerate(scenario.actors):
        tr = actor.trajectory
        color = cmap(k % 10)
        ax.plot(tr.x, tr.y, lw=1.3, color=color, zorder=2,
                label="actors" if k == 0 else None)
        ax.plot(tr.x[:1], tr.y[:1], "s", ms=3.5, color=color, zorder=2)
        if len(scenario.actors) <= 25:
            ax.annotate(actor.id, (tr.x[-1], tr.y[-1]), fontsize=7, color=color)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_title("Route: roads, ego and actor trajectories (ENU, circle/square = start)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return _png(fig)


def _lane_width_m(scenario: Scenario) -> float:
    return scenario.roads[0].lane_width_m if scenario.roads else LANE_WIDTH_M


def lead_series(scenario: Scenario, rate_hz: float = LEAD_SAMPLE_HZ) -> dict[str, np.ndarray]:
    """Lead vehicle over time (:func:`vid2sim.core.lead.lead_of`): the nearest actor ahead whose
    centre lies within half a lane width of the path the ego drove, measured along that path
    (:class:`vid2sim.evaluate.scenetime.SceneClock`, as the environment measures it).

    Returns
    -------
    dict
        ``t_s``, ``range_m`` (ego origin to the lead's rear, NaN without a lead),
        ``lead_speed_mps``, ``ego_speed_mps`` and ``lead_id`` (object array, "" without one).
    """
    ego = scenario.ego.trajectory
    n = max(2, math.floor(ego.duration_s * rate_hz) + 1)
    t = np.linspace(ego.t[0], ego.t[-1], n)
    rng = np.full(n, np.nan)
    lead_v = np.full(n, np.nan)
    ego_v = np.full(n, np.nan)
    lead_id = np.full(n, "", dtype=object)
    # the lead along the ego's driven path (THE lead rule, as the environment and the replay
    # video measure it): in a bend the ego's straight axis leaves the lane
    clock = SceneClock(scenario)
    for k, tk in enumerate(t):
        pose, actors = clock.at(float(tk))
        ego_v[k] = pose.speed_mps
        lead = clock.lead(pose, actors)
        if lead is not None:
            rng[k], lead_v[k], lead_id[k] = lead.range_m, lead.speed_mps, lead.id
    return {"t_s": t, "range_m": rng, "lead_speed_mps": lead_v, "ego_speed_mps": ego_v,
            "lead_id": lead_id}


def lead_figure(scenario: Scenario) -> bytes:
    """PNG of the lead range and of ego and lead speeds over time."""
    s = lead_series(scenario)
    fig = Figure(figsize=(9.0, 5.2))
    ax1 = fig.add_subplot(2, 1, 1)
    ax2 = fig.add_subplot(2, 1, 2, sharex=ax1)
    ax1.plot(s["t_s"], s["range_m"], color="#c0392b", lw=1.8)
    ax1.set_ylabel("lead range [m]")
    ax1.set_title("Lead vehicle (nearest actor ahead within the ego lane)")
    ax1.grid(True, alpha=0.3)
    if np.isnan(s["range_m"]).all():
        ax1.text(0.5, 0.5, "no vehicle ahead in the ego lane", transform=ax1.transAxes,
                 ha="center", va="center", color="#4a5468")
    ax2.plot(s["t_s"], s["ego_speed_mps"], color="#1f5fbf", lw=1.8, label="ego")
    ax2.plot(s["t_s"], s["lead_speed_mps"], color="#c0392b", lw=1.5, label="lead")
    ax2.set_xlabel("time from the video's first frame [s]")
    ax2.set_ylabel("speed [m/s]")
    ax2.grid(True, alpha=0.3)
    ax2.legend(loc="best", fontsize=8)
    return _png(fig)


# --------------------------------------------------------------------------- HTML pieces


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _image_bytes(img: ImageLike) -> tuple[bytes, str]:
    """(bytes, mime type) of an image given as bytes or a file path."""
    if isinstance(img, (bytes, bytearray)):
        data = bytes(img)
    else:
        p = Path(img)
        try:
            data = p.read_bytes()
        except OSError as exc:
            raise MissingInputError(p, f"cannot read figure: {exc}") from None
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return data, "image/png"
    if data[:3] == b"\xff\xd8\xff":
        return data, "image/jpeg"
    if data.lstrip()[:5] in (b"<?xml", b"<svg ") or b"<svg" in data[:200]:
        return data, "image/svg+xml"
    raise FormatError(None, "figure is not a PNG, JPEG or SVG image")


KEYFRAME_MAX_WIDTH_PX = 960
"""Keyframe photos wider than this are downscaled in the report (the PNG files keep full size)."""
KEYFRAME_JPEG_QUALITY = 85


def _as_jpeg(data: bytes, mime: str) -> tuple[bytes, str]:
    """Camera frames as JPEG (about a tenth of the PNG), at most ``KEYFRAME_MAX_WIDTH_PX``
    wide, so a report with a hundred keyframes stays a few megabytes."""
    if mime == "image/svg+xml":
        return data, mime
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        return data, mime
    if img.shape[1] > KEYFRAME_MAX_WIDTH_PX:
        h = round(img.shape[0] * KEYFRAME_MAX_WIDTH_PX / img.shape[1])
        img = cv2.resize(img, (KEYFRAME_MAX_WIDTH_PX, h), interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, KEYFRAME_JPEG_QUALITY])
    return (buf.tobytes(), "image/jpeg") if ok else (data, mime)


def _figure_html(title: str, img: ImageLike, photo: bool = False) -> str:
    data, mime = _image_bytes(img)
    if photo:
        data, mime = _as_jpeg(data, mime)
    b64 = base64.b64encode(data).decode("ascii")
    return (f'<figure><img alt="{_e(title)}" src="data:{mime};base64,{b64}">'
            f"<figcaption>{_e(title)}</figcaption></figure>")


def _linked_figure_html(title: str, img: Path, href: str) -> str:
    """A photo embedded small (JPEG) that opens the full-size file ``href`` on click."""
    data, mime = _as_jpeg(*_image_bytes(img))
    b64 = base64.b64encode(data).decode("ascii")
    return (f'<figure><a href="{_e(href)}" target="_blank"><img alt="{_e(title)}" '
            f'src="data:{mime};base64,{b64}"></a><figcaption>{_e(title)} '
            f'(click for full size)</figcaption></figure>')


def _events_html(scenario: Scenario) -> str:
    """The scenario's events with the video frame of each (frame rate from the source)."""
    if not scenario.events:
        return ""
    fps = scenario.source.options.get("fps")
    fps = float(fps) if isinstance(fps, (int, float)) and not isinstance(fps, bool) else None
    rows = "".join(
        f"<tr><td class='l'>{_e(e.type)}</td><td class='l'>{_e(e.actor)}</td>"
        f"<td>{e.t_s:.2f}</td><td>{round(e.t_s * fps) if fps else 'n/a'}</td>"
        f"<td>{e.from_lane:+d} &rarr; {e.to_lane:+d}</td></tr>" for e in scenario.events)
    return ("<section><h2>Events (lanes relative to the ego lane: 0 the ego lane, +1 left, "
            "-1 right)</h2><table><tr><th class='l'>type</th><th class='l'>actor</th>"
            "<th>t [s]</th><th>frame</th><th>lanes</th></tr>" + rows + "</table></section>")


def _num(x: Any, spec: str = ".3f") -> str:
    if x is None:
        return "n/a"
    if isinstance(x, bool):
        return str(x)
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        return "n/a" if not math.isfinite(x) else format(x, spec)
    return _e(x)


def _inputs_html(scenario: Scenario, inputs: Any) -> str:
    src = scenario.source
    columns: list[str] = []
    for item in src.inputs:
        if isinstance(item, dict):
            columns.extend(k for k in item if k not in columns)
    rows = []
    for item in src.inputs:
        if isinstance(item, dict):
            rows.append("<tr>" + "".join(f"<td class='l'>{_e(item.get(k, ''))}</td>"
                                         for k in columns) + "</tr>")
        else:
            rows.append(f"<tr><td class='l' colspan='{max(1, len(columns))}'>{_e(item)}</td></tr>")
    header = ("<tr>" + "".join(f"<th class='l'>{_e(k)}</th>" for k in columns) + "</tr>"
              if columns else "<tr><th class='l'>scenario inputs</th></tr>")
    parts = ["<section><h2>Inputs and assumptions</h2>"]
    parts.append(f"<p class='small'>Scenario built by vid2sim {_e(src.tool_version or '?')}; "
                 f"origin lat {scenario.origin.lat:.6f}, lon {scenario.origin.lon:.6f}; "
                 f"duration {scenario.duration_s:.1f} s; {len(scenario.actors)} actors; "
                 f"{len(scenario.roads)} road(s).</p>")
    if rows:
        parts.append("<p class='small'>scenario inputs</p><table>" + header + "".join(rows)
                     + "</table>")
    if inputs:
        if isinstance(inputs, dict):
            items = [f"<tr><td class='l'>{_e(k)}</td><td class='l'>{_e(v)}</td></tr>"
                     for k, v in inputs.items()]
        else:
            items = [f"<tr><td class='l' colspan='2'>{_e(v)}</td></tr>" for v in inputs]
        parts.append("<table><tr><th class='l' colspan='2'>this run</th></tr>" + "".join(items)
                     + "</table>")
    if src.options:
        parts.append("<p class='small'>options</p><pre>"
                     + _e(json.dumps(src.options, indent=1, sort_keys=True, default=str))
                     + "</pre>")
    if src.settings:
        parts.append("<details><summary class='small'>every setting the scenario was made with "
                     "(<code>source.settings</code>; <code>vid2sim settings</code> prints the "
                     "defaults, <code>--config</code> changes them)</summary><pre>"
                     + _e(json.dumps(src.settings, indent=1, default=str)) + "</pre></details>")
    if src.assumptions:
        parts.append("<p><b>Assumptions</b></p><ul>"
                     + "".join(f"<li>{_e(a)}</li>" for a in src.assumptions) + "</ul>")
    else:
        parts.append("<p class='small'>The scenario records no assumptions.</p>")
    parts.append("</section>")
    return "".join(parts)


def _metrics_html(m: dict) -> str:
    ref = m.get("reference_study", {})
    rng = m.get("range_error") or {}
    kpis = [("keyframes", m.get("keyframes")), ("F1", m.get("f1")),
            ("precision", m.get("precision")), ("recall", m.get("recall")),
            ("mean IoU", m.get("mean_iou"))]
    if rng.get("pairs"):
        kpis.append(("mean |range error| [m]", rng.get("mean_abs_m")))
    out = ["<section><h2>Keyframe metrics</h2><div class='kpi'>"]
    out += [f"<div>{_e(k)}<b>{_num(v)}</b></div>" for k, v in kpis]
    out.append("</div><table><tr><th class='l'>counting</th><th>TP</th><th>FP</th><th>FN</th>"
               "<th>precision</th><th>recall</th><th>F1</th><th>mean IoU</th></tr>")
    out.append(f"<tr><td class='l'>standard</td><td>{_num(m.get('tp'))}</td>"
               f"<td>{_num(m.get('fp'))}</td><td>{_num(m.get('fn'))}</td>"
               f"<td>{_num(m.get('precision'))}</td><td>{_num(m.get('recall'))}</td>"
               f"<td>{_num(m.get('f1'))}</td><td>{_num(m.get('mean_iou'))}</td></tr>")
    if ref:
        out.append(f"<tr><td class='l'>reference study</td><td>{_num(ref.get('tp'))}</td>"
                   f"<td>{_num(ref.get('fp'))}</td><td>{_num(ref.get('fn'))}</td>"
                   f"<td>{_num(ref.get('precision'))}</td><td>{_num(ref.get('recall'))}</td>"
                   f"<td>{_num(ref.get('f1'))}</td><td>{_num(ref.get('mean_iou'))}</td></tr>")
    out.append("</table>")
    if m.get("projection"):
        out.append(f"<p class='small'>Simulated vehicles projected as: "
                   f"{_e(m['projection'])}; replay: {_e(m.get('replay', ''))}.</p>")
    if rng.get("pairs"):
        out.append("<table><tr><th class='l'>range error (simulated - annotated)</th>"
                   "<th>pairs</th><th>mean |e| [m]</th><th>median |e| [m]</th><th>RMSE [m]</th>"
                   "<th>mean signed [m]</th><th>mean |e|/range</th></tr>"
                   f"<tr><td class='l'>matched vehicles with 3D annotation</td>"
                   f"<td>{_num(rng.get('pairs'))}</td><td>{_num(rng.get('mean_abs_m'), '.2f')}</td>"
                   f"<td>{_num(rng.get('median_abs_m'), '.2f')}</td>"
                   f"<td>{_num(rng.get('rmse_m'), '.2f')}</td>"
                   f"<td>{_num(rng.get('mean_signed_m'), '+.2f')}</td>"
                   f"<td>{_num(rng.get('mean_abs_rel'), '.3f')}</td></tr></table>")
    per = m.get("per_keyframe") or []
    if per:
        out.append("<table><tr><th class='l'>keyframe</th><th>t [s]</th><th>annotated</th>"
                   "<th>simulated</th><th>TP</th><th>FP</th><th>FN</th><th>F1</th>"
                   "<th>mean IoU</th><th>ref. TP/FP/FN</th></tr>")
        for k in per:
            r = k.get("reference_study", {})
            out.append(f"<tr><td class='l'>{_e(k.get('name'))}</td><td>{_num(k.get('t_s'), '.2f')}"
                       f"</td><td>{_num(k.get('annotated'))}</td><td>{_num(k.get('simulated'))}"
                       f"</td><td>{_num(k.get('tp'))}</td><td>{_num(k.get('fp'))}</td>"
                       f"<td>{_num(k.get('fn'))}</td><td>{_num(k.get('f1'))}</td>"
                       f"<td>{_num(k.get('mean_iou'))}</td>"
                       f"<td>{_num(r.get('tp'))}/{_num(r.get('fp'))}/{_num(r.get('fn'))}</td></tr>")
        out.append("</table>")
    defs = m.get("definitions")
    if defs:
        out.append("<p class='small'><b>Definitions.</b> "
                   + " ".join(f"<i>{_e(k)}</i>: {_e(v)}." for k, v in defs.items()) + "</p>")
    out.append("</section>")
    return "".join(out)


# --------------------------------------------------------------------------- replay video

#: Where the replay video's section sits in a report: between these markers, so that
#: ``vid2sim render`` can put one into the report of a finished build (or replace it).
REPLAY_START, REPLAY_END = "<!--vid2sim:replay-->", "<!--/vid2sim:replay-->"


def replay_section(href: str, moments: Sequence[tuple[str, float, int | None]], *,
                   t_from_s: float = 0.0, caption: str = "", playable: bool = True) -> str:
    """The report's replay section: a ``<video controls>`` element playing ``href``
    (relative to the report) and a table of the moments to look at, each linked to its time
    in the video (a media fragment, ``href#t=seconds``: the browser opens the video there).

    Parameters
    ----------
    href : the video's address relative to the report
    moments : (what happens, scenario time [s], video frame or None) of each row
    t_from_s : the scenario time of the video's first frame [s]
    caption : a line about the video (frames, size, codec)
    playable : False for a codec browsers do not play (the section then says so)
    """
    rows = []
    for what, t_s, frame in moments:
        at = max(t_s - t_from_s, 0.0)
        rows.append(f"<tr><td class='l'>{_e(what)}</td><td>{t_s:.2f}</td>"
                    f"<td>{'' if frame is None else frame}</td><td class='l'><a href="
                    f"'{_e(href)}#t={at:.2f}' target='_blank'>play from {at:.1f} s</a></td></tr>")
    note = ("" if playable else "<p class='small'><b>This video is MPEG-4 part 2, which "
            "browsers do not play</b>: open it with a video player (VLC, mpv), or install a PyAV "
            "whose FFmpeg has libx264 and render again for H.264.</p>")
    table = ("<table><tr><th class='l'>moment</th><th>t [s]</th><th>frame</th><th class='l'>"
             "</th></tr>" + "".join(rows) + "</table>") if rows else ""
    return (f"{REPLAY_START}<section id='replay'><h2>Replay: the video with the tracked boxes "
            "and the scenario's vehicles projected back (outline colour: IoU with the "
            "detection), the scenario from above (right), time, speeds, lead and TTC "
            f"(bottom)</h2><video controls preload='metadata' src='{_e(href)}' "
            f"style='width:100%;height:auto;background:#000'>"
            f"<a href='{_e(href)}'>{_e(href)}</a></video>"
            f"<p class='small'>{_e(caption)} <a href='{_e(href)}'>{_e(href)}</a></p>{note}"
            f"{table}</section>{REPLAY_END}")


def with_replay(report_html: str, section: str) -> str:
    """The report's text with its replay section replaced by ``section`` (put after the
    header where a report of an older version has none)."""
    start, end = report_html.find(REPLAY_START), report_html.find(REPLAY_END)
    if start >= 0 and end > start:
        return report_html[:start] + section + report_html[end + len(REPLAY_END):]
    at = report_html.find("<main>")
    if at < 0:
        raise FormatError(None, "not a vid2sim report (no <main> element)")
    at += len("<main>")
    return report_html[:at] + section + report_html[at:]


# --------------------------------------------------------------------------- the report


def render_report(*, scenario: Scenario, metrics: dict | None,
                  keyframe_images: Sequence[tuple[str, ImageLike]] = (),
                  extra_figures: Sequence[tuple[str, ImageLike]] = (),
                  warnings: Sequence[str] = (), inputs: Any = None,
                  title: str = "vid2sim scenario report",
                  frame_images: Sequence[tuple[str, Path, str]] = (),
                  replay: str | None = None) -> str:
    """The report's HTML text (see :func:`write_report`; ``replay``: the replay section,
    :func:`replay_section`)."""
    parts = ["<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
             "<meta name='viewport' content='width=device-width, initial-scale=1'>",
             f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>",
             f"<header><h1>{_e(title)}</h1><p>vid2sim {_e(__version__)} &middot; "
             f"{len(scenario.actors)} actors &middot; {scenario.duration_s:.1f} s"
             + (f" &middot; keyframe F1 {_num(metrics.get('f1'))}" if metrics else "")
             + "</p></header><main>"]
    if warnings:
        parts.append("<section class='warn'><h2>Warnings</h2><ul>"
                     + "".join(f"<li>{_e(w)}</li>" for w in warnings) + "</ul></section>")
    # the replay video's place (vid2sim render fills it)
    parts.append(replay or REPLAY_START + REPLAY_END)
    parts.append(_inputs_html(scenario, inputs))
    if metrics:
        parts.append(_metrics_html(metrics))
    if keyframe_images:
        parts.append("<section><h2>Keyframes: annotated boxes (green), simulated vehicles "
                     "(magenta), ignore regions (grey)</h2><div class='grid'>"
                     + "".join(_figure_html(t, img, photo=True) for t, img in keyframe_images)
                     + "</div></section>")
    parts.append(_events_html(scenario))
    if frame_images:
        parts.append("<section><h2>Sampled frames: tracked boxes (#id, lane L relative to the "
                     "ego lane, range; orange the ego lane, blue left, green right, grey other "
                     "or unknown, the lead thicker), the ego lane's boundaries (yellow), and the "
                     "simulator at the same moment (right; ego in green)</h2><div "
                     "class='frames'>" + "".join(_linked_figure_html(t, img, href)
                                                 for t, img, href in frame_images)
                     + "</div></section>")
    parts.append("<section><h2>Map and lead vehicle</h2><div class='grid'>"
                 + _figure_html("Roads, ego and actor trajectories", map_figure(scenario))
                 + _figure_html("Lead range and speeds", lead_figure(scenario))
                 + "</div></section>")
    if extra_figures:
        parts.append("<section><h2>More figures</h2><div class='grid'>"
                     + "".join(_figure_html(t, img) for t, img in extra_figures)
                     + "</div></section>")
    parts.append("</main></body></html>\n")
    return "".join(parts)


def write_report(path: str | Path, *, scenario: Scenario, metrics: dict | None,
                 keyframe_images: Sequence[tuple[str, ImageLike]] = (),
                 extra_figures: Sequence[tuple[str, ImageLike]] = (),
                 warnings: Sequence[str] = (), inputs: Any = None,
                 title: str = "vid2sim scenario report",
                 frame_images: Sequence[tuple[str, Path, str]] = ()) -> None:
    """Write one self-contained HTML report atomically.

    Parameters
    ----------
    path : path
        Output ``.html`` file.
    scenario : Scenario
        Source of the inputs/assumptions, map and lead plots.
    metrics : dict or None
        The metrics.json content, or None when no keyframes were evaluated.
    keyframe_images : sequence of (title, PNG bytes or path)
        Overlays shown side by side.
    extra_figures : sequence of (title, PNG/JPEG/SVG bytes or path)
        Figures from other stages (road map, ranging plots).
    warnings : sequence of str
        Shown first.
    inputs : dict or list, optional
        What this run was given (file names, options).
    frame_images : sequence of (title, image path, link relative to the report)
        Sampled frames (:mod:`vid2sim.evaluate.frames`), embedded small, opening the file
        at full size on click.
    """
    text = render_report(scenario=scenario, metrics=metrics, keyframe_images=keyframe_images,
                         extra_figures=extra_figures, warnings=warnings, inputs=inputs,
                         title=title, frame_images=frame_images)
    write_text_atomic(path, text)
