"""When to run the detector: keyframes by time, sooner when the tracks need a fresh look.

The full detector (full frame, tiles, centre window, refine crops) costs several network runs;
between its keyframes the tracks' boxes are carried by optical flow
(:mod:`vid2sim.detect.tracking.flow`), which keeps per-frame box measurements for range and range
rate. A frame is a keyframe when

* it is the first, or ``keyframe_s`` or more after the last keyframe (so sparse input, whose
  frames are that far apart, is detected on every frame);
* the last keyframe started a confident track that has not had its second look (the
  tracker's confirmation, and its test of a one-frame false detection, need the next frame);
* optical flow failed on a confirmed track not cut by the image border (occlusion, motion
  blur, a fast scene; a car leaving the view loses its flow as a matter of course);
* the lead candidate's carried box changed its size by more than ``max_scale_change``
  since it was last detected (its range comes from the box: the detector's box is wanted);
* the lead candidate changed (the nearest box ahead, :func:`~vid2sim.detect.vehicles.windows.refine_candidates`).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

from vid2sim.core.boxes import border_cut
from vid2sim.detect.tracking.tracker import Tracker
from vid2sim.detect.vehicles.windows import refine_candidates

TIME_TOLERANCE_S = 1e-3
"""Keyframes are due a hair before the interval: container timestamps of a 10 fps video are
0.1 s give or take a millisecond."""


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
    """

    keyframe_s: float = 0.3
    max_scale_change: float = 0.15
    second_look: bool = True
    lead_change: bool = True


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
        self._last_key_t_s: float | None = None
        self._want_next: str | None = "first"
        self._lead_id: int | None = None
        self.n_keyframes = 0
        self.n_frames = 0
        self.reasons: Counter[str] = Counter()  # why keyframes were run, for benchmarks

    def is_keyframe(self, t_s: float) -> bool:
        """Whether the detector should run on the frame at ``t_s`` [s]."""
        self.n_frames += 1
        cfg = self.config
        reason = self._want_next
        if reason is None and (cfg.keyframe_s <= 0 or self._last_key_t_s is None or
                               t_s - self._last_key_t_s >= cfg.keyframe_s - TIME_TOLERANCE_S):
            reason = "interval"
        if reason is None:
            return False
        self.reasons[reason] += 1
        self.n_keyframes += 1
        self._last_key_t_s = t_s
        self._want_next = None
        return True

    def after_keyframe(self, tracker: Tracker, t_s: float) -> None:
        """Look at the tracks after a keyframe: a young confident track wants a second look."""
        if self.config.second_look and any(t.born_t_s == t_s and not t.weak and not t.confirmed
                                           for t in tracker.tracks()):
            self._want_next = "new track"
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
        for t in tracker.tracks():
            if t.track_id not in carried:
                continue
            # a car leaving the view at the border loses its flow: no reason to look again
            if not carried[t.track_id] and t.confirmed and t.track_id not in cut:
                self._want_next = "flow failed"
                return
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
