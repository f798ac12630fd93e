"""Streamed video input: frames one at a time from a video file or a folder of images."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Collection, Iterator
from pathlib import Path

import cv2
import numpy as np

from vid2sim.base.errors import FormatError, ImpossibleValueError, InconsistentInputError
from vid2sim.core.records import Frame
from vid2sim.core.videofile import (
    image_files,
    open_capture,
    resume_after,
    undecodable,
    video_info,
)

PREFETCH_FRAMES = 4
"""Frames decoded ahead by :func:`prefetch`: enough to cover a keyframe's detector time at
30 fps, little memory (4 x 6 MB at 1080p)."""
MAX_NUMBERING_GAP = 1000
"""Image names ending in frame numbers count as a numbering (``000010.png``, ``000015.png``:
every 5th frame) when no two neighbours are more than this many frames apart; larger gaps
mean the digits are something else (a clock in ns, a date)."""


def frame_numbers(files: list[Path]) -> list[int] | None:
    """The frame numbers at the end of the file names (``frame_000123.png`` -> 123), if every
    name has one and they increase by 1 to ``MAX_NUMBERING_GAP``; else None."""
    numbers = []
    for f in files:
        stem = f.stem
        digits = stem[len(stem.rstrip("0123456789")):]
        if not digits:
            return None
        numbers.append(int(digits))
    gaps = np.diff(numbers)
    if len(gaps) and not ((gaps >= 1) & (gaps <= MAX_NUMBERING_GAP)).all():
        return None
    return numbers


def folder_frame_steps(path: Path) -> list[int] | None:
    """For an image folder whose names carry frame numbers: the number of each image counted
    from the first (``000010, 000015, 000020`` -> 0, 5, 10); None for a video or a folder
    without a numbering."""
    path = Path(path)
    if not path.is_dir():
        return None
    numbers = frame_numbers(image_files(path))
    return None if numbers is None else [n - numbers[0] for n in numbers]

__all__ = ["folder_frame_steps", "frame_numbers", "iter_frames", "prefetch", "video_info"]


def iter_frames(path: Path, every: int = 1, fps: float | None = None,
                skipped: list[int] | None = None,
                only: Collection[int] | None = None) -> Iterator[Frame]:
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
        them (see :func:`vid2sim.core.videofile.resume_after`).
    only : collection of int, optional
        Decode these frames (0-based) instead of every N-th: the others are grabbed (or not
        read) as above, so the timestamps stay the container's.

    Raises
    ------
    InputError
        If the path is missing or unreadable, no frame decodes, a folder's images differ in
        size, or ``every < 1``.
    """
    path = Path(path)
    if every < 1:
        raise ImpossibleValueError(None, f"--detect-every must be >= 1, got {every}")
    info = video_info(path, fps=fps)
    lost = skipped if skipped is not None else []
    wanted = frozenset(int(i) for i in only) if only is not None else None

    def decode(index: int) -> bool:
        return index in wanted if wanted is not None else index % every == 0

    if path.is_dir():
        yield from _iter_folder(path, decode, info.fps, (info.width, info.height), lost)
    else:
        yield from _iter_video(path, decode, info.fps, info.n_frames, lost)


def _iter_folder(folder: Path, decode: Callable[[int], bool], fps: float,
                 size: tuple[int, int], skipped: list[int]) -> Iterator[Frame]:
    n_read = n_tried = 0
    for index, file in enumerate(image_files(folder)):
        image = None
        if decode(index):
            n_tried += 1
            image = cv2.imread(str(file), cv2.IMREAD_COLOR)
            if image is None:
                skipped.append(index)
                continue
            if (image.shape[1], image.shape[0]) != size:
                raise InconsistentInputError(file, f"frame is {image.shape[1]}x{image.shape[0]} px, the "
                                 f"folder's frames are {size[0]}x{size[1]}",
                                 "the frames of one video share one size")
            n_read += 1
        yield Frame(index=index, t_s=index / fps, image_bgr=image)
    if n_read == 0 and n_tried > 0:
        raise FormatError(folder, "none of the folder's images can be decoded")


def _iter_video(path: Path, decode: Callable[[int], bool], fps: float, n_declared: int,
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
            if decode(index):
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
            raise undecodable(path, "video has no decodable frames")
    finally:
        cap.release()


def prefetch(frames: Iterator[Frame], depth: int = PREFETCH_FRAMES) -> Iterator[Frame]:
    """Iterate ``frames`` with decoding in a background thread, up to ``depth`` frames ahead.

    OpenCV's decoders and onnxruntime release the GIL, so decoding the next frames overlaps
    the detector's work on this one. Errors raised by the reader (an :class:`InputError` on a
    truncated video) are raised here, in the caller's thread, at the frame where they
    occurred. Closing the generator stops the reader.
    """
    buffer: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
    stop = threading.Event()
    done = object()

    def read() -> None:
        try:
            for frame in frames:
                while not stop.is_set():
                    try:
                        buffer.put(frame, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            buffer.put(done)
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer, raised there
            buffer.put(exc)

    reader = threading.Thread(target=read, name="vid2sim-decode", daemon=True)
    reader.start()
    try:
        while True:
            item = buffer.get()
            if item is done:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        # unblock a reader waiting on a full buffer, then let it finish
        while reader.is_alive():
            try:
                buffer.get_nowait()
            except queue.Empty:
                reader.join(timeout=0.05)
        close = getattr(frames, "close", None)
        if close is not None:
            close()
