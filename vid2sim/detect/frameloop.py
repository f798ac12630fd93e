"""One frame at a time through the keyframe schedule: detect (all windows or a band) or carry
the boxes by optical flow, then track; and the rows of the frames between analysed ones.

:class:`ScheduledTracking` is the per-frame work of :func:`vid2sim.detect.pipeline.run_detect`
with a detector and a keyframe schedule; :class:`Looks` says where each keyframe looks;
:func:`fill_between` interpolates the boxes of the frames a fast video skips (analysed at
:attr:`~vid2sim.detect.schedule.ScheduleConfig.analysis_hz`), after the ranging, so that the
ranging too costs what a 10 Hz video does.

The detector runs ahead of the tracker, in a worker thread: both cores busy for the whole run.

The grid keyframes (:class:`~vid2sim.detect.schedule.KeyframeGrid`) are known from the frames'
times alone, so their detector run can start as soon as the frame is decoded, while the main
thread still carries and tracks the frames before it; onnxruntime and OpenCV release the GIL.
:func:`lookahead` holds a few decoded frames ahead of the main loop and shows each to a
visitor as it enters (which plans and submits its detection); :class:`DetectAhead` runs the
submitted detections one at a time in its thread and hands each result back when the main
loop reaches its frame. Back-pressure: the main loop pulls at most ``depth`` frames ahead, so
at most ``depth`` images and results wait in memory; the decoding thread's own queue
(:func:`~vid2sim.detect.video.prefetch`) is bounded too.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from itertools import pairwise
from typing import TypeVar

import numpy as np

from vid2sim.core.records import Detection, Frame, TrackedBox
from vid2sim.detect.schedule import LOCAL, SWEEP, KeyframeSchedule, ScheduleConfig, band_rows
from vid2sim.detect.tracking.flow import MedianFlow
from vid2sim.detect.tracking.tracker import Tracker
from vid2sim.detect.vehicles.detector import Detector
from vid2sim.detect.vehicles.windows import (
    Look,
    band_look,
    local_look,
    net_scale,
    seen_by,
    tracks_look,
)

AHEAD_FRAMES = 4
"""Frames the main loop pulls ahead of the one it tracks: a grid keyframe every 3rd frame at
10 frames/s is then submitted 1-4 frames (30-60 ms of carrying and tracking) before it is
needed, about one detector run; 4 frames of 1080p are 25 MB."""


def lookahead(frames: Iterator[Frame], depth: int, visit: Callable[[Frame], None]
              ) -> Iterator[Frame]:
    """``frames`` in order, each shown to ``visit`` (in the caller's thread) ``depth`` frames
    before it is yielded."""
    buffer: deque[Frame] = deque()
    for frame in frames:
        visit(frame)
        buffer.append(frame)
        if len(buffer) > depth:
            yield buffer.popleft()
    while buffer:
        yield buffer.popleft()


class DetectAhead:
    """Detector runs submitted ahead, run in order in one worker thread.

    Parameters
    ----------
    detector : Detector
        Its ``detect(image, look)`` runs in the worker thread (and may run in the main
        thread at the same time: onnxruntime sessions are thread-safe).
    """

    def __init__(self, detector: Detector):
        self.detector = detector
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="vid2sim-detect")
        self._pending: dict[int, tuple[str, Look | None, Future]] = {}

    def submit(self, index: int, image_bgr: np.ndarray, kind: str, look: Look | None) -> None:
        """Start the detector on frame ``index`` (looking at ``look``, all windows if None)."""
        future = self._pool.submit(_detect, self.detector, image_bgr, look)
        self._pending[index] = (kind, look, future)

    def take(self, index: int) -> tuple[str, Look | None, list[Detection]] | None:
        """The kind, look and detections of frame ``index`` (waiting for them), or None if
        none was submitted. Frames before ``index`` that were never taken are dropped."""
        for old in [k for k in self._pending if k < index]:
            self._pending.pop(old)[2].cancel()
        item = self._pending.pop(index, None)
        if item is None:
            return None
        kind, look, future = item
        return kind, look, future.result()

    def close(self) -> None:
        """Cancel what has not started and wait for the worker to finish."""
        for _, _, future in self._pending.values():
            future.cancel()
        self._pending.clear()
        self._pool.shutdown(wait=True)


def _detect(detector: Detector, image_bgr: np.ndarray, look: Look | None) -> list[Detection]:
    return detector.detect(image_bgr) if look is None else detector.detect(image_bgr, look)


B = TypeVar("B", bound=TrackedBox)


class Looks:
    """Where a keyframe's detector looks, from the tracker's state (see
    :mod:`vid2sim.detect.schedule`): every window on a sweep, the full frame and a band of
    rows otherwise. A detector without windows (no ``full_look``) always looks everywhere.

    Parameters
    ----------
    detector : Detector
    image_size_px : (int, int)
        Frame width and height [px].
    config : ScheduleConfig
    horizon_row_px : float, optional
        Image row of the horizon [px] (the camera's); default the image's middle row.
    """

    def __init__(self, detector: Detector, image_size_px: tuple[int, int],
                 config: ScheduleConfig, horizon_row_px: float | None = None):
        self.config = config
        self.image_size_px = (int(image_size_px[0]), int(image_size_px[1]))
        w, h = self.image_size_px
        self.horizon_row_px = h / 2.0 if horizon_row_px is None else float(horizon_row_px)
        self.full = detector.full_look(w, h) if hasattr(detector, "full_look") else None
        self.input_size_px = tuple(getattr(detector, "input_size_px", (w, h)))
        self.enabled = self.full is not None and len(self.full.windows) > 1

    def look(self, kind: str, tracker: Tracker, focus: tuple[int, ...] = ()) -> Look | None:
        """The windows of a ``kind`` keyframe (``LOCAL``: about the tracks ``focus``); None
        for every window."""
        if not self.enabled or kind == SWEEP:
            return None
        if kind == LOCAL:
            boxes = [t.kf.box_px for t in tracker.tracks() if t.track_id in set(focus)]
            return local_look(np.array(boxes, dtype=float).reshape(-1, 4), self.full,
                              self.input_size_px, self.image_size_px)
        if self.config.between == "tracks":
            boxes = np.array([t.kf.box_px for t in tracker.tracks()], dtype=float)
            return tracks_look(boxes.reshape(-1, 4), self.full, self.input_size_px,
                               self.image_size_px)
        full_scale = net_scale(self.full.windows[0], self.input_size_px)
        rows = band_rows(tracker, self.config, self.image_size_px[1], full_scale,
                         self.horizon_row_px)
        look = band_look(self.full, rows)
        return None if look.windows == self.full.windows else look

    def seen(self, look: Look | None) -> Callable[[np.ndarray], np.ndarray] | None:
        """The tracker's test of what ``look`` looked at (None: everything)."""
        if look is None or look.sweep:
            return None
        full, size, cfg = self.full, self.input_size_px, self.config
        return lambda boxes: seen_by(boxes, look, full, size, cfg.min_net_px, self.image_size_px)


class ScheduledTracking:
    """The detector on keyframes, optical flow between, the tracker on every analysed frame.

    Call :meth:`visit` on each frame a few frames ahead (:func:`~vid2sim.detect.frameloop.lookahead`:
    it plans the grid's keyframes and, with ``ahead``, starts their detector runs), then
    :meth:`step` on each in order.
    """

    def __init__(self, detector: Detector, tracker: Tracker, keys: KeyframeSchedule,
                 carrier: MedianFlow, looks: Looks, ahead: DetectAhead | None = None):
        self.detector = detector
        self.tracker = tracker
        self.keys = keys
        self.carrier = carrier
        self.looks = looks
        self.ahead = ahead
        self._planned: dict[int, tuple[str, Look | None]] = {}

    def visit(self, frame: Frame) -> None:
        """Plan frame ``frame`` (ahead of :meth:`step`): a grid keyframe's look, and its
        detector run started in the worker."""
        if frame.image_bgr is None or not self.keys.config.fixed_grid:
            return
        kind = self.keys.grid.plan(frame.t_s)
        if kind is None:
            return
        look = self.looks.look(kind, self.tracker)
        if self.ahead is not None:
            self.ahead.submit(frame.index, frame.image_bgr, kind, look)
        else:
            self._planned[frame.index] = (kind, look)

    def step(self, frame: Frame) -> list[TrackedBox]:
        """Detect or carry ``frame``, track; its rows."""
        planned = self._take(frame.index)
        if not self.keys.config.fixed_grid:  # planned now, after any restart of the grid
            kind = self.keys.grid.plan(frame.t_s)
            planned = None if kind is None else (kind, self.looks.look(kind, self.tracker))
        kind = self.keys.decide(frame.t_s, None if planned is None else planned[0])
        if kind is None:
            return self._carried(frame)
        if planned is not None and len(planned) == 3:
            _, look, found = planned
        else:
            look = (planned[1] if planned is not None
                    else self.looks.look(kind, self.tracker, self.keys.focus))
            found = (self.detector.detect(frame.image_bgr) if look is None
                     else self.detector.detect(frame.image_bgr, look))
        out = self._detected(frame, found, self.looks.seen(look))
        self.keys.after_keyframe(self.tracker, frame.t_s)
        return out

    def _take(self, index: int):
        if self.ahead is not None:
            return self.ahead.take(index)
        for old in [k for k in self._planned if k < index]:
            del self._planned[old]
        return self._planned.pop(index, None)

    def _detected(self, frame: Frame, found: list[Detection],
                  seen: Callable[[np.ndarray], np.ndarray] | None) -> list[TrackedBox]:
        """A keyframe's tracking; where the detector did not look (``seen``), the shown boxes
        are carried by flow."""
        if seen is None:
            self.carrier.carry(frame.image_bgr, [], frame.index)  # keeps this frame
            return self.tracker.update(frame.index, frame.t_s, found)
        ids, boxes = self.tracker.shown_boxes()
        moved, ok = self.carrier.carry(frame.image_bgr, boxes, frame.index)
        measured = {tid: moved[i] for i, tid in enumerate(ids) if ok[i]}
        return self.tracker.update(frame.index, frame.t_s, found, measured=measured, seen=seen)

    def _carried(self, frame: Frame) -> list[TrackedBox]:
        """A frame between keyframes: the shown boxes carried by flow."""
        ids, boxes = self.tracker.shown_boxes()
        moved, ok = self.carrier.carry(frame.image_bgr, boxes, frame.index)
        out = self.tracker.update(frame.index, frame.t_s, None,
                                  measured={tid: moved[i] for i, tid in enumerate(ids) if ok[i]})
        self.keys.after_carry(self.tracker, {tid: bool(ok[i]) for i, tid in enumerate(ids)})
        return out


INTERPOLATED_FIELDS = ("x1", "y1", "x2", "y2", "range_m", "lateral_m", "range_rate_mps",
                       "range_std_m", "width_m", "lateral_rate_mps", "lane_offset_m")
"""Fields of a tracked (or ranged) box interpolated between two analysed frames; the others
(score, category, lead, lane) are the earlier frame's."""


def fill_between(boxes: list[B], frame_times_s: dict[int, float], step: int) -> list[B]:
    """The rows of a video analysed on every ``step``-th frame, with a row added on every
    frame between two analysed frames for each track seen on both: its fields interpolated
    linearly in time (the frame's time from ``frame_times_s``, 0-based index -> s; frames
    absent from it get no row). Sorted by frame, then track; ``step`` 1 returns ``boxes``."""
    if step <= 1 or not boxes:
        return boxes
    by_track: dict[int, list[B]] = {}
    for b in sorted(boxes, key=lambda b: (b.track_id, b.frame)):
        by_track.setdefault(b.track_id, []).append(b)
    names = [f for f in INTERPOLATED_FIELDS if f in boxes[0].__dataclass_fields__]
    out = list(boxes)
    for rows in by_track.values():
        for a, b in pairwise(rows):
            if b.frame - a.frame != step:
                continue
            for frame in range(a.frame + 1, b.frame):
                if frame in frame_times_s:
                    out.append(_between(a, b, frame, frame_times_s[frame], names))
    out.sort(key=lambda r: (r.frame, r.track_id))
    return out


def _between(a: B, b: B, frame: int, t_s: float, names: list[str]) -> B:
    w = (t_s - a.t_s) / (b.t_s - a.t_s) if b.t_s > a.t_s else 0.0
    values = {n: getattr(a, n) + w * (getattr(b, n) - getattr(a, n)) for n in names}
    return replace(a, frame=frame, t_s=t_s, **values)
