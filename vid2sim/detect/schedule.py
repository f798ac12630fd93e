"""When to run the detector, and where it looks: keyframes on a time grid, sooner when the
tracks need a fresh look; a full sweep on a slower cadence, the tracks alone between.

The full detector (full frame, tiles, centre window, refine crops) costs several network runs;
between its keyframes the tracks' boxes are carried by optical flow
(:mod:`vid2sim.detect.tracking.flow`), which keeps per-frame box measurements for range and range
rate. A frame is a keyframe when

* it is on the grid: the first frame, then the first frame ``keyframe_s`` or more after the
  last grid keyframe (so sparse input, whose frames are that far apart, is detected on every
  frame). The grid depends on the frames' times only (:class:`KeyframeGrid`), so the detector
  can run on a grid keyframe ahead of the tracker (:mod:`vid2sim.detect.frameloop`);
* the last keyframe started a confident track that has not had its second look (the
  tracker's confirmation, and its test of a one-frame false detection, need the next frame);
* optical flow failed on a confirmed track not cut by the image border (occlusion, motion
  blur, a fast scene; a car leaving the view loses its flow as a matter of course);
* the lead candidate's carried box changed its size by more than ``max_scale_change``
  since it was last detected (its range comes from the box: the detector's box is wanted);
* the lead candidate changed (the nearest box ahead, :func:`~vid2sim.detect.vehicles.windows.refine_candidates`).

Where it looks (:class:`~vid2sim.detect.vehicles.windows.Look`): a grid keyframe ``sweep_s``
or more after the last full sweep (and the first frame, and every frame of sparse input) runs
every window. The grid keyframes between run the full frame (near cars anywhere, and cars
entering at the image's sides, are large) and a crop about every track at the scale a sweep
would see it at (``between="tracks"``); new far cars wait for the next sweep. A keyframe the
tracks asked for (a second look, a failed flow) looks at those tracks alone. The tracker is
told what was looked at (:func:`~vid2sim.detect.vehicles.windows.seen_by`), so a track the
detector did not look at is carried by flow rather than missed.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from vid2sim.core.boxes import border_cut
from vid2sim.detect.tracking.tracker import Tracker
from vid2sim.detect.vehicles.windows import refine_candidates

TIME_TOLERANCE_S = 1e-3
"""Keyframes are due a hair before the interval: container timestamps of a 10 fps video are
0.1 s give or take a millisecond."""

SWEEP = "sweep"
"""A keyframe that runs every window of the detector."""
BAND = "band"
"""A keyframe that runs the full frame and the windows cut to a band (:func:`band_rows`)."""
LOCAL = "local"
"""A keyframe the tracks asked for that looks only at those tracks (crops about them, each
at the scale a sweep would see it at: a new track's second look, a failed flow)."""
LOCAL_REASONS = frozenset({"new track", "flow failed"})
"""Why a keyframe looks at its tracks only (the others, the lead's, look at the band)."""


@dataclass(frozen=True, slots=True)
class ScheduleConfig:
    """Keyframe rules.

    :param keyframe_s: longest time between two detector keyframes [s]; 0 runs the detector
        on every frame. Composite clips (6 seeds, lanes every 0.2 s, one refined box; the
        detector on every frame: lead range 2.9 %, rate RMSE 0.594 m/s): 0.2 s 2.5 % / 0.617
        (54 % of frames detected), 0.3 s 2.4 % / 0.629 (41 %), 0.4 s and 0.5 s rate RMSE
        0.67 and 0.75: 0.3 s (every 3rd frame at 10 fps, every 9th at 30 fps)
    :param max_scale_change: a carried lead box whose height changed by more than this
        fraction since its last detection asks for a keyframe
    :param second_look: detect on the frame after a keyframe that started a confident track
    :param lead_change: detect when the lead candidate changes
    :param sweep_s: a grid keyframe this long or more after the last full sweep runs every
        window [s]; the grid keyframes between look at the tracks (``between``); 0: every
        grid keyframe is a full sweep. 0.9 s (every third grid keyframe): the keyframes
        between cost 356 kpx of the net's input against a sweep's 609 kpx on KITTI raw
        0001; on its forward-and-back clip 1168 boxes matched to the lidar tracklets
        against 1164 with every keyframe a sweep (range median |error| 9.6 against 9.0 %,
        range-rate median |error| 2.10 against 1.89 m/s), composite clips' lead range-rate
        RMSE 0.63 against 0.66 m/s (docs/performance.md); a new far car waits up to 0.9 s
        there. Default 0 (every grid keyframe a sweep): with 0.9 s the parked cars of KITTI
        raw 0001 under 10 m read 5.7 % against the tracklet floor of 5.5 %, and the
        tracker's accuracy comes before the 28 % of CPU it saves (docs/performance.md)
    :param min_net_px: a vehicle whose box is at least this tall in the net's input is taken
        as found wherever a window holds it (YOLOX-nano's finest head has a stride of 8 px:
        three cells; the full KITTI frame, at a third of its size, finds the parked cars
        from about 70 px of frame height, 24 px at the net)
    :param band_above, band_below: the band's rows about the horizon: from ``band_above``
        to ``band_below`` times the height of the smallest box the full frame finds (its
        ``min_net_px``) above and below the horizon row (a car's top stands near the horizon
        and its bottom, on a flat road, about 1.1 of its height below; KITTI raw 0001's boxes
        under 72 px lie in rows 142-280, horizon 187: -0.63..+1.29 of 72 px)
    :param band_margin: rows kept about each small track's predicted box, as a fraction of
        its height (its motion over the frames the plan is made ahead, and the tracker's
        prediction error)
    :param analysis_hz: frames of a faster video analysed per second (every
        ``round(fps / analysis_hz)``-th frame decoded, detected or carried; the boxes of the
        frames between are interpolated): 10 Hz, the rate the tracker, the schedule and
        the ranging were tuned at on KITTI's 10 fps drives, so a 30 fps video costs about
        what a 10 fps one does per second of video; the scenario keeps the video's rate
    :param fixed_grid: the grid's keyframes keep their times whatever keyframes the tracks
        asked for in between, so they are known ahead and detected in a worker thread
        (:mod:`vid2sim.detect.frameloop`); False counts the interval from the last keyframe of
        any kind (fewer keyframes, all detected in turn)
    :param local_looks: a keyframe the tracks asked for (a second look, a failed flow)
        looks at those tracks only; False (default, with ``sweep_s`` 0): a full sweep
    :param between: what a grid keyframe between two sweeps looks at: ``"tracks"``, the
        full frame and a crop about every track at the scale a sweep sees it at
        (:func:`~vid2sim.detect.vehicles.windows.tracks_look`), or ``"band"``, the full frame
        and the sweep's other windows cut to a band of rows about the horizon
        (:func:`band_rows`; it lost 4 % of the boxes matched to the tracklets and raised
        the range-rate bias from +1.3 to +2.5 m/s: the band leaves mid-sized cars to the
        full frame's coarse boxes)
    """

    keyframe_s: float = 0.3
    max_scale_change: float = 0.15
    second_look: bool = True
    lead_change: bool = True
    sweep_s: float = 0.0
    min_net_px: float = 24.0
    band_above: float = 0.75
    band_below: float = 1.5
    band_margin: float = 0.5
    analysis_hz: float = 10.0
    fixed_grid: bool = True
    local_looks: bool = False
    between: str = "tracks"

    def analysis_step(self, fps: float) -> int:
        """Frames per analysed frame of a ``fps`` video (1 up to ``1.5 * analysis_hz``)."""
        if self.analysis_hz <= 0 or not math.isfinite(fps) or fps <= 0:
            return 1
        return max(1, round(fps / self.analysis_hz))


class KeyframeGrid:
    """The keyframes due by time alone, frame by frame in order: :meth:`plan` returns
    ``SWEEP``, ``BAND`` or None. It sees only the frames' times, so it can be run on frames
    ahead of the tracker."""

    def __init__(self, config: ScheduleConfig):
        self.config = config
        self._last_t_s: float | None = None
        self._last_sweep_t_s: float | None = None
        self._prev_t_s: float | None = None

    def restart(self, t_s: float) -> None:
        """A keyframe the tracks asked for ran at ``t_s``: without ``fixed_grid`` the next
        grid keyframe is due ``keyframe_s`` after it."""
        if not self.config.fixed_grid:
            self._last_t_s = t_s

    def plan(self, t_s: float) -> str | None:
        """The grid's keyframe at ``t_s`` [s] (frames in order), or None."""
        cfg = self.config
        prev, self._prev_t_s = self._prev_t_s, t_s
        due = (cfg.keyframe_s <= 0 or self._last_t_s is None
               or t_s - self._last_t_s >= cfg.keyframe_s - TIME_TOLERANCE_S)
        if not due:
            return None
        self._last_t_s = t_s
        sparse = prev is not None and t_s - prev >= cfg.keyframe_s - TIME_TOLERANCE_S
        if (cfg.sweep_s <= 0 or self._last_sweep_t_s is None or sparse
                or t_s - self._last_sweep_t_s >= cfg.sweep_s - TIME_TOLERANCE_S):
            self._last_sweep_t_s = t_s
            return SWEEP
        return BAND


class KeyframeSchedule:
    """Decides frame by frame whether the detector runs (see the module docstring).

    Parameters
    ----------
    config : ScheduleConfig
    image_width_px : int
        Frame width, to find the lead candidate (box centre near the image centre line).
    """

    def __init__(self, config: ScheduleConfig, image_width_px: int):
        self.config = config
        self.image_width_px = int(image_width_px)
        self.grid = KeyframeGrid(config)
        self._want_next: str | None = None
        self._focus: tuple[int, ...] = ()
        self.focus: tuple[int, ...] = ()  # the tracks the last LOCAL keyframe looks at
        self._lead_id: int | None = None
        self._first = True
        self.look = SWEEP  # where the last keyframe looked
        self.n_keyframes = 0
        self.n_frames = 0
        self.reasons: Counter[str] = Counter()  # why keyframes were run, for benchmarks
        self.looks: Counter[str] = Counter()  # sweeps and band keyframes, for benchmarks

    def is_keyframe(self, t_s: float) -> bool:
        """Whether the detector should run on the frame at ``t_s`` [s], with the schedule's
        own grid (frames in order; see :meth:`decide` for a grid planned ahead)."""
        return self.decide(t_s, self.grid.plan(t_s)) is not None

    def decide(self, t_s: float, planned: str | None) -> str | None:
        """Where the detector looks on the frame at ``t_s`` [s] (``SWEEP``, ``BAND`` or
        ``LOCAL``: then at the tracks in :attr:`focus`), or None when it does not run;
        ``planned`` is the grid's plan for the frame (:meth:`KeyframeGrid.plan`). A keyframe
        the tracks asked for looks at them (a second look, a failed flow), else at the band
        if band keyframes are on (``sweep_s``), else everywhere."""
        self.n_frames += 1
        first, self._first = self._first, False
        grid_reason = None if planned is None else "sweep" if planned == SWEEP else "interval"
        reason = "first" if first else (self._want_next or grid_reason)
        if reason is None:
            return None
        local = self.config.local_looks and reason in LOCAL_REASONS
        banded = self.config.sweep_s > 0  # band keyframes enabled
        self.look = planned or (SWEEP if first else LOCAL if local else BAND if banded
                                else SWEEP)
        if planned is None:
            self.grid.restart(t_s)
        self.focus = self._focus if self.look == LOCAL else ()
        self.reasons[reason] += 1
        self.looks[self.look] += 1
        self.n_keyframes += 1
        self._want_next, self._focus = None, ()
        return self.look

    def after_keyframe(self, tracker: Tracker, t_s: float) -> None:
        """Look at the tracks after a keyframe: a young confident track wants a second look."""
        young = tuple(t.track_id for t in tracker.tracks()
                      if t.born_t_s == t_s and not t.weak and not t.confirmed)
        if self.config.second_look and young:
            self._want_next, self._focus = "new track", young
        self._lead_id = self._lead(tracker)

    def after_carry(self, tracker: Tracker, carried: dict[int, bool]) -> None:
        """Look at the tracks after a frame carried by flow (``carried``: track id -> flow
        succeeded) and ask for a keyframe next if they need one."""
        cfg = self.config
        limit = math.log1p(cfg.max_scale_change)
        ids, boxes = tracker.shown_boxes()
        on_border = border_cut(boxes, tracker.image_size_px,
                               tracker.config.border_margin_px).any(axis=1)
        cut = {tid for tid, c in zip(ids, on_border, strict=True) if c}
        # a car leaving the view at the border loses its flow: no reason to look again
        failed = tuple(t.track_id for t in tracker.tracks()
                       if t.track_id in carried and not carried[t.track_id] and t.confirmed
                       and t.track_id not in cut)
        if failed:
            self._want_next, self._focus = "flow failed", failed
            return
        for t in tracker.tracks():
            if t.track_id not in carried:
                continue
            if t.track_id != self._lead_id:
                continue
            h_det = t.last_box_px[3] - t.last_box_px[1]
            h_now = t.shown_box_px[3] - t.shown_box_px[1]
            if h_det > 0 and h_now > 0 and abs(math.log(h_now / h_det)) > limit:
                self._want_next = "scale change"
                return
        if cfg.lead_change and self._lead(tracker) != self._lead_id:
            self._want_next = "lead change"

    def _lead(self, tracker: Tracker) -> int | None:
        ids, boxes = tracker.shown_boxes()
        confirmed = {t.track_id for t in tracker.tracks() if t.confirmed}
        keep = [i for i, tid in enumerate(ids) if tid in confirmed]
        if not keep:
            return None
        best = refine_candidates(boxes[keep], self.image_width_px, 1)
        return None if len(best) == 0 else ids[keep[int(best[0])]]


def band_rows(tracker: Tracker, config: ScheduleConfig, image_height_px: int,
              full_scale: float, horizon_row_px: float) -> tuple[float, float]:
    """Rows (y1, y2) [px] of the band a ``BAND`` keyframe looks at beyond the full frame:
    ``band_above``..``band_below`` of the smallest box the full frame finds about the horizon
    row, widened to every live track smaller than that (its predicted box and
    ``band_margin`` of its height about it), clipped to the image.

    ``full_scale`` is the full frame's net pixels per frame pixel
    (:func:`~vid2sim.detect.vehicles.windows.net_scale`).
    """
    small_px = config.min_net_px / max(full_scale, 1e-6)
    y1 = horizon_row_px - config.band_above * small_px
    y2 = horizon_row_px + config.band_below * small_px
    boxes = np.array([t.kf.box_px for t in tracker.tracks()], dtype=float).reshape(-1, 4)
    height = boxes[:, 3] - boxes[:, 1]
    small = boxes[(height < small_px) & (height > 0)]
    if len(small):
        margin = config.band_margin * (small[:, 3] - small[:, 1])
        y1 = min(y1, float((small[:, 1] - margin).min()))
        y2 = max(y2, float((small[:, 3] + margin).max()))
    return max(0.0, y1), min(float(image_height_px), y2)
