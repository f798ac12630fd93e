"""Streamed video input: frames one at a time from a video file or a folder of images."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from vid2sim.errors import InputError
from vid2sim.records import Frame
from vid2sim.videofile import image_files, open_capture, resume_after, video_info

__all__ = ["iter_frames", "video_info"]

def iter_frames(path: Path, every: int = 1, fps: float | None = None,
                skipped: list[int] | None = None) -> Iterator[Frame]:
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
    skipped : list of int, optional
        Receives the indices of frames that could not be read (corrupt bytes, a decoder that
        stopped early, an unreadable image); they are not yielded, the stream goes on after
        them (see :func:`vid2sim.videofile.resume_after`).

    Raises
    ------
    InputError
        If the path is missing or unreadable, no frame decodes, a folder's images differ in
        size, or ``every < 1``.
    """
    path = Path(path)
    if every < 1:
        raise InputError(None, f"--detect-every must be >= 1, got {every}")
    info = video_info(path, fps=fps)
    lost = skipped if skipped is not None else []
    if path.is_dir():
        yield from _iter_folder(path, every, info.fps, (info.width, info.height), lost)
    else:
        yield from _iter_video(path, every, info.fps, info.n_frames, lost)


def _iter_folder(folder: Path, every: int, fps: float, size: tuple[int, int],
                 skipped: list[int]) -> Iterator[Frame]:
    n_read = 0
    for index, file in enumerate(image_files(folder)):
        image = None
        if index % every == 0:
            image = cv2.imread(str(file), cv2.IMREAD_COLOR)
            if image is None:
                skipped.append(index)
                continue
            if (image.shape[1], image.shape[0]) != size:
                raise InputError(file, f"frame is {image.shape[1]}x{image.shape[0]} px, the "
                                 f"folder's frames are {size[0]}x{size[1]}",
                                 "the frames of one video share one size")
            n_read += 1
        yield Frame(index=index, t_s=index / fps, image_bgr=image)
    if n_read == 0:
        raise InputError(folder, "none of the folder's images can be decoded")


def _iter_video(path: Path, every: int, fps: float, n_declared: int,
                skipped: list[int]) -> Iterator[Frame]:
    cap = open_capture(path)
    try:
        index = 0
        n_yielded = 0
        t0_ms: float | None = None
        last_t_s = -np.inf
        while True:
            if not cap.grab():
                # Before the declared end the decoder stopped at damaged bytes: go past them.
                resume = resume_after(cap, index, n_declared) if index < n_declared else None
                if resume is None:
                    skipped.extend(range(index, max(index, n_declared)))
                    break
                skipped.extend(range(index, resume))
                index = resume
            pos_ms = cap.get(cv2.CAP_PROP_POS_MSEC)
            if t0_ms is None:
                t0_ms = pos_ms - 1000.0 * index / fps
            t_s = (pos_ms - t0_ms) / 1000.0
            # Some containers (raw streams, broken indices) report 0 or repeat a time:
            # the nominal rate is then the only clock we have.
            if not np.isfinite(t_s) or (n_yielded > 0 and t_s <= last_t_s):
                t_s = index / fps
            image = None
            if index % every == 0:
                ok, image = cap.retrieve()
                if not ok:
                    skipped.append(index)
                    index += 1
                    continue
            last_t_s = t_s
            yield Frame(index=index, t_s=t_s, image_bgr=image)
            n_yielded += 1
            index += 1
        if n_yielded == 0:
            raise InputError(path, "video has no decodable frames")
    finally:
        cap.release()
