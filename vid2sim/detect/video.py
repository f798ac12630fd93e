"""Streamed video input: frames one at a time from a video file or a folder of images."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from vid2sim.errors import InputError
from vid2sim.records import Frame
from vid2sim.videofile import image_files, open_capture, video_info

__all__ = ["iter_frames", "video_info"]

def iter_frames(path: Path, every: int = 1, fps: float | None = None) -> Iterator[Frame]:
    """Stream the frames of a video file or image folder, decoding only every N-th one.

    Every frame of the source is yielded in order, so the caller sees the full time base;
    frames whose index is not a multiple of ``every`` carry ``image_bgr=None``: for a video
    they are grabbed without ``retrieve`` (the codec still decodes them, since later frames
    depend on them, but no BGR conversion or copy is made), for a folder the image is not
    read. Only one frame is held in memory at a time.

    Timestamps ``t_s`` come from the container (``CAP_PROP_POS_MSEC``) relative to the first
    frame, so variable-rate videos keep their true clock; where the container gives no usable
    time (zero or not increasing) ``index / fps`` is used instead. Image folders are sorted by
    name and timed at ``fps`` (default 10 frames/s).

    Parameters
    ----------
    path : Path
        Video file or image folder.
    every : int
        Decode every N-th frame (1 = all).
    fps : float, optional
        Frame rate [frames/s] for image folders or videos without one.

    Raises
    ------
    InputError
        If the path is missing or unreadable, or ``every < 1``.
    """
    path = Path(path)
    if every < 1:
        raise InputError(None, f"--detect-every must be >= 1, got {every}")
    info = video_info(path, fps=fps)
    if path.is_dir():
        yield from _iter_folder(path, every, info.fps)
    else:
        yield from _iter_video(path, every, info.fps)


def _iter_folder(folder: Path, every: int, fps: float) -> Iterator[Frame]:
    for index, file in enumerate(image_files(folder)):
        image = None
        if index % every == 0:
            image = cv2.imread(str(file), cv2.IMREAD_COLOR)
            if image is None:
                raise InputError(file, "cannot read this image", "is the file complete?")
        yield Frame(index=index, t_s=index / fps, image_bgr=image)


def _iter_video(path: Path, every: int, fps: float) -> Iterator[Frame]:
    cap = open_capture(path)
    try:
        index = 0
        t0_ms: float | None = None
        last_t_s = -np.inf
        while cap.grab():
            pos_ms = cap.get(cv2.CAP_PROP_POS_MSEC)
            if t0_ms is None:
                t0_ms = pos_ms
            t_s = (pos_ms - t0_ms) / 1000.0
            # Some containers (raw streams, broken indices) report 0 or repeat a time:
            # the nominal rate is then the only clock we have.
            if not np.isfinite(t_s) or (index > 0 and t_s <= last_t_s):
                t_s = index / fps
            last_t_s = t_s
            image = None
            if index % every == 0:
                ok, image = cap.retrieve()
                if not ok:
                    raise InputError(path, f"cannot decode frame {index}",
                                     "the video may be truncated; re-encode it with ffmpeg")
            yield Frame(index=index, t_s=t_s, image_bgr=image)
            index += 1
        if index == 0:
            raise InputError(path, "video has no decodable frames")
    finally:
        cap.release()
