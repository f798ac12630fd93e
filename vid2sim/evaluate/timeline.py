"""The strip under a replay: a line of numbers at the current time over two small plots of
the whole clip with a cursor.

The line says the time, the ego speed, the lead's range, closing speed and time to
collision, and the events as they happen (an event's caption stays
:attr:`StripConfig.event_show_s`). The plots show whole series (the upper one typically
the lead's range, the lower one speeds), a band under them coloured by the TTC (red below
:attr:`StripConfig.ttc_critical_s`, yellow below :attr:`StripConfig.ttc_warn_s`, green
above, nothing without a closing lead), and a tick for every event, bright once it has
happened. The plots are drawn once (:class:`Strip`), each frame only adds the cursor, the
ticks passed and the line of numbers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from vid2sim.evaluate.replayconfig import StripConfig

_BG = (32, 32, 32)
_AXIS = (90, 90, 90)
_TEXT = (235, 235, 235)
_DIM = (120, 120, 120)
_CRITICAL, _WARN, _OK = (50, 50, 230), (0, 200, 240), (60, 170, 60)


@dataclass(frozen=True, slots=True)
class Trace:
    """One series of a plot: times [s], values, BGR colour and ``style`` (``line``,
    ``dashed`` or ``dots``)."""

    label: str
    t_s: np.ndarray
    values: np.ndarray
    colour: tuple[int, int, int]
    style: str = "line"


@dataclass(frozen=True, slots=True)
class Moment:
    """Something that happened at ``t_s`` [s]: an event, a collision, an AEB brake."""

    t_s: float
    label: str
    colour: tuple[int, int, int] = (255, 255, 255)


@dataclass(slots=True)
class Plot:
    """One of the two plots: its traces and the axis label (unit included)."""

    label: str
    traces: list[Trace] = field(default_factory=list)


def ttc_s(range_m: np.ndarray, closing_mps: np.ndarray) -> np.ndarray:
    """Time to collision [s]: range over closing speed where closing (> 0.1 m/s), else inf;
    NaN where the range is unknown (no lead)."""
    r = np.asarray(range_m, dtype=float)
    v = np.asarray(closing_mps, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(v > 0.1, np.maximum(r, 0.0) / v, np.inf)
    return np.where(np.isfinite(r), out, np.nan)


class Strip:
    """The strip (module docstring) for the clip ``[t0_s, t1_s]``, ``width x height`` px."""

    def __init__(self, width_px: int, height_px: int, t0_s: float, t1_s: float,
                 plots: Sequence[Plot], ttc: tuple[np.ndarray, np.ndarray] | None = None,
                 moments: Sequence[Moment] = (), config: StripConfig | None = None):
        self.config = config or StripConfig()
        self.width, self.height = int(width_px), int(height_px)
        self.t0, self.t1 = float(t0_s), float(max(t1_s, t0_s + 1e-3))
        self.font = max(0.42, self.height / 260.0)
        self.small = 0.8 * self.font
        line_h = cv2.getTextSize("Ag", cv2.FONT_HERSHEY_SIMPLEX, self.font, 1)[0][1]
        small_h = cv2.getTextSize("0", cv2.FONT_HERSHEY_SIMPLEX, self.small, 1)[0][1]
        self.text_y = line_h + 6
        self.left = cv2.getTextSize("888", cv2.FONT_HERSHEY_SIMPLEX, self.small, 1)[0][0] + 10
        self.right = 8
        self.moments = sorted(moments, key=lambda m: m.t_s)
        band = max(6, round(self.height * 0.05))
        top = self.text_y + 8
        bottom = self.height - small_h - 8 - band
        rows = max(len(plots), 1)
        step = (bottom - top) / rows
        self._rows = [(round(top + k * step), round(top + (k + 1) * step) - 3)
                      for k in range(rows)]
        self._band = (bottom + 2, bottom + 2 + band)
        self.background = self._draw_background(plots, ttc)

    def x_px(self, t_s: float | np.ndarray) -> np.ndarray:
        """Pixel column of a time."""
        span = self.width - self.left - self.right
        return self.left + (np.asarray(t_s, float) - self.t0) / (self.t1 - self.t0) * span

    def _draw_background(self, plots, ttc) -> np.ndarray:
        img = np.full((self.height, self.width, 3), _BG, np.uint8)
        for (y0, y1), plot in zip(self._rows, plots, strict=False):
            self._draw_plot(img, plot, y0, y1)
        if ttc is not None:
            self._draw_ttc_band(img, *ttc)
        # time axis: a tick per second (per 10 s, a minute on long clips), labelled every 5
        span = self.t1 - self.t0
        step = 1.0 if span <= 60 else 10.0 if span <= 600 else 60.0
        for t in np.arange(math.ceil(self.t0 / step) * step, self.t1 + 1e-9, step):
            x = int(self.x_px(t))
            cv2.line(img, (x, self._band[1]), (x, self._band[1] + 3), _AXIS, 1)
            if round(t / step) % 5 == 0:
                _put(img, f"{t:g} s", (x - 6, self.height - 3), self.small, _DIM)
        for m in self.moments:
            x = int(self.x_px(m.t_s))
            cv2.line(img, (x, self._rows[0][0]), (x, self._band[1]), _DIM, 1, cv2.LINE_AA)
        return img

    def _draw_plot(self, img: np.ndarray, plot: Plot, y0: int, y1: int) -> None:
        x0, x1 = self.left, self.width - self.right
        cv2.rectangle(img, (x0, y0), (x1, y1), _AXIS, 1)
        finite = [v[np.isfinite(v)] for v in (np.asarray(tr.values, float) for tr in plot.traces)]
        known = [v for v in finite if v.size]
        top = max(max(float(v.max()) for v in known) * 1.1, 1.0) if known else 1.0
        _put(img, f"{top:.0f}", (3, y0 + 10), self.small, _DIM)
        _put(img, "0", (3, y1), self.small, _DIM)
        for tr in plot.traces:
            x = self.x_px(tr.t_s)
            y = y1 - np.asarray(tr.values, float) / top * (y1 - y0)
            pts = np.column_stack((x, y))
            ok = np.isfinite(pts).all(axis=1)
            if tr.style == "dots":
                for u, v in np.round(pts[ok]).astype(int):
                    cv2.circle(img, (int(u), int(v)), 1, tr.colour, -1, cv2.LINE_AA)
                continue
            for a, e in _runs(ok):
                seg = np.round(pts[a:e]).astype(np.int32)
                pieces = ([seg[i:i + 2] for i in range(0, len(seg) - 1, 2)]
                          if tr.style == "dashed" else [seg])
                cv2.polylines(img, pieces, False, tr.colour, 1, cv2.LINE_AA)
        u = x0 + 6
        for item, colour in [(plot.label, _TEXT)] + [(tr.label, tr.colour) for tr in plot.traces]:
            _put(img, item, (u, y0 + 4 + round(12 * self.small / 0.4)), self.small, colour)
            u += cv2.getTextSize(item, cv2.FONT_HERSHEY_SIMPLEX, self.small, 1)[0][0] + 14
        if not known:
            _put(img, "none", (u, y0 + 4 + round(12 * self.small / 0.4)), self.small, _DIM)

    def _draw_ttc_band(self, img: np.ndarray, t_s: np.ndarray, ttc: np.ndarray) -> None:
        cfg = self.config
        ya, yb = self._band
        x = self.x_px(t_s)
        for i in range(len(t_s) - 1):
            v = ttc[i]
            if not np.isfinite(v):  # no lead (NaN) or not closing (inf): no colour
                continue
            colour = _CRITICAL if v < cfg.ttc_critical_s else _WARN if v < cfg.ttc_warn_s else _OK
            cv2.rectangle(img, (int(x[i]), ya), (max(int(x[i + 1]) - 1, int(x[i])), yb), colour,
                          cv2.FILLED)
        _put(img, "TTC", (3, yb), self.small, _DIM)

    def draw(self, t_s: float, line: str, colour: tuple[int, int, int] = _TEXT) -> np.ndarray:
        """The strip at ``t_s``: the background, the ticks of the moments passed, the cursor,
        ``line`` and the captions of the moments of the last few seconds."""
        img = self.background.copy()
        top, bottom = self._rows[0][0], self._band[1]
        captions = []
        for m in self.moments:
            if m.t_s > t_s + 1e-9:
                break
            x = int(self.x_px(m.t_s))
            cv2.line(img, (x, top), (x, bottom), m.colour, 2, cv2.LINE_AA)
            if t_s - m.t_s <= self.config.event_show_s:
                captions.append(m)
        x = int(self.x_px(min(max(t_s, self.t0), self.t1)))
        cv2.line(img, (x, top - 2), (x, bottom + 2), (255, 255, 255), 1)
        _put(img, line, (6, self.text_y), self.font, colour)
        u = 6 + cv2.getTextSize(line, cv2.FONT_HERSHEY_SIMPLEX, self.font, 1)[0][0] + 20
        for m in reversed(captions):
            _put(img, m.label, (u, self.text_y), self.font, m.colour)
            u += cv2.getTextSize(m.label, cv2.FONT_HERSHEY_SIMPLEX, self.font, 1)[0][0] + 14
        return img


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate(([False], np.asarray(mask, bool), [False])).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(),
                    strict=True))


def _put(img: np.ndarray, text: str, org, scale: float, colour) -> None:
    cv2.putText(img, text, (int(org[0]), int(org[1])), cv2.FONT_HERSHEY_SIMPLEX, scale, colour,
                1, cv2.LINE_AA)
