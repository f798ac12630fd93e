"""The detector ahead of the tracker, in a worker thread: both cores busy for the whole run.

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

import numpy as np

from vid2sim.core.records import Detection, Frame
from vid2sim.detect.vehicles.detector import Detector
from vid2sim.detect.vehicles.windows import Look

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
