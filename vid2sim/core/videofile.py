"""What a video file or folder of images is, and random access to its frames.

One frame numbering for every stage: a folder's images in name order (``.png``, ``.jpg``,
``.jpeg``), a video's frames in decoding order. :mod:`vid2sim.detect.video` streams frames
with this numbering; evaluation reads single keyframes with it.

Damaged input: the images of a folder must share one size (an input error naming the first
that does not); a video whose decoder stops before the frames its container declares is
resumed past the damage (:func:`resume_after`), and the frames lost are counted and
reported by the caller (:func:`skipped_frames_note`). Damage the decoder conceals (a smeared
block in an otherwise decodable frame) is invisible through OpenCV and goes unreported.
"""

from __future__ import annotations

import functools
import math
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
from PIL import Image, UnidentifiedImageError

from vid2sim.base.defaults import IMAGE_FOLDER_FPS
from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    InputError,
    MissingInputError,
)
from vid2sim.core.container import UNKNOWN_CODEC, codec_of
from vid2sim.core.records import VideoInfo

#: Largest frame side [px]: 8K video is 7680 px wide; a larger "frame" is not a video's.
MAX_FRAME_SIDE_PX = 16384

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def image_files(folder: Path) -> list[Path]:
    """The images of a folder used as a video, in name order (frame i is the i-th)."""
    files = sorted(p for p in folder.iterdir()
                   if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise MissingInputError(folder, "folder holds no .png/.jpg images",
                                "give a video file or a folder of frames named in time order")
    return files


def open_capture(path: Path) -> cv2.VideoCapture:
    """An opened OpenCV capture, or an input error naming the file."""
    if not path.exists():
        raise MissingInputError(path, "no such video file or folder")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        cap.release()
        raise undecodable(path, "OpenCV cannot open this video")
    return cap


def undecodable(path: Path, problem: str) -> InputError:
    """The error for a video whose frames OpenCV cannot give, naming its codec where FFmpeg's
    demuxer can read the container (an unknown or undecodable codec, e.g. HEVC on a build
    without an HEVC decoder)."""
    codec = codec_of(path)
    if codec == UNKNOWN_CODEC:
        return FormatError(path, f"{problem}: its video codec is unknown to FFmpeg",
                           "convert it to H.264 with ffmpeg")
    if codec is not None:
        return FormatError(path, f"{problem}: the installed decoder cannot decode its {codec} "
                           "video", f"install an OpenCV build whose FFmpeg decodes {codec}, or "
                           "convert it to H.264 with ffmpeg")
    return FormatError(path, problem, "check the file is a complete video (mp4/avi/mov) or "
                       "convert it with ffmpeg")


def video_info(path: Path, fps: float | None = None) -> VideoInfo:
    """Size, frame rate and frame count of a video file or image folder.

    Parameters
    ----------
    path : Path
        Video file, or folder of images sorted by name.
    fps : float, optional
        Frame rate [frames/s] to assume for an image folder (default 10) or to override a
        video's missing rate.

    Raises
    ------
    InputError
        If the path is missing or unreadable.
    """
    path = Path(path)
    if path.is_dir():
        files = image_files(path)
        width, height = folder_frame_size(path)
        return VideoInfo(width=width, height=height, fps=float(fps or IMAGE_FOLDER_FPS),
                         n_frames=len(files))
    cap = open_capture(path)
    try:
        rate = cap.get(cv2.CAP_PROP_FPS)
        rate = float(fps) if fps else (rate if rate and np.isfinite(rate) and rate > 0 else 0.0)
        if rate <= 0:
            raise FormatError(
                path, "video declares no frame rate", "pass the frame rate explicitly")
        count = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        width, height = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        if not (0 < width <= MAX_FRAME_SIDE_PX and 0 < height <= MAX_FRAME_SIDE_PX):
            raise ImpossibleValueError(path, f"frames of {width}x{height} px are not a video's "
                                       f"(at most {MAX_FRAME_SIDE_PX} px a side)")
        return VideoInfo(width=width, height=height, fps=rate,
                         n_frames=int(count) if math.isfinite(count) and count > 0 else 0)
    finally:
        cap.release()


def folder_frame_size(folder: Path) -> tuple[int, int]:
    """(width, height) [px] shared by every image of a folder used as a video.

    Read from the image headers (no decoding), so a folder of thousands of frames is checked
    in a second, before any detection. Images whose header cannot be read are left to the
    frame reader, which counts them as corrupt frames.

    Raises
    ------
    InputError
        If the images differ in size (naming the first that differs from the most common
        size), none can be read, or the size is not a video frame's.
    """
    folder = Path(folder)
    try:
        stamp = folder.stat().st_mtime_ns
    except OSError as exc:
        raise MissingInputError(folder, f"cannot read: {exc.strerror or exc}") from None
    return _folder_frame_size(str(folder.resolve()), stamp)


@functools.lru_cache(maxsize=8)
def _folder_frame_size(folder: str, _mtime_ns: int) -> tuple[int, int]:
    # Cached per folder and modification time: every stage asks for the video's facts.
    sizes: dict[Path, tuple[int, int]] = {}
    for f in image_files(Path(folder)):
        try:
            with Image.open(f) as img:
                sizes[f] = (int(img.width), int(img.height))
        except Image.DecompressionBombError:
            raise ImpossibleValueError(f, "image far larger than a video frame") from None
        except (OSError, UnidentifiedImageError, ValueError):
            continue
    if not sizes:
        raise FormatError(folder, "none of the folder's images can be read",
                          "are the files complete images?")
    common, _ = Counter(sizes.values()).most_common(1)[0]
    odd = [(f, wh) for f, wh in sizes.items() if wh != common]
    if odd:
        f, (w, h) = odd[0]
        raise InconsistentInputError(
            f, f"frame is {w}x{h} px but {len(sizes) - len(odd)} of the folder's "
            f"{len(sizes)} frames are {common[0]}x{common[1]} "
            f"({len(odd)} frame(s) of another size)",
            "the frames of one video share one size; resize or remove the others")
    if not (0 < common[0] <= MAX_FRAME_SIDE_PX and 0 < common[1] <= MAX_FRAME_SIDE_PX):
        raise ImpossibleValueError(
            folder, f"frames of {common[0]}x{common[1]} px are not a video's "
            f"(at most {MAX_FRAME_SIDE_PX} px a side)")
    return common


def resume_after(cap: cv2.VideoCapture, failed: int, n_declared: int) -> int | None:
    """Resume decoding after the decoder failed to give frame ``failed``.

    A video with damaged bytes stops decoding at the damage although its container declares
    ``n_declared`` frames (a mp4 with 400 kB overwritten mid-file: 57 of 108 frames, silently).
    Seeking past the damage recovers the rest: the first later frame that decodes is found by
    doubling the step, then bisecting back (a few seeks, each a keyframe decode).

    Returns
    -------
    int or None
        The index of the first decodable frame after ``failed`` (the capture has grabbed it,
        ready for ``retrieve``), or None if none of the declared frames after it decodes.
    """
    def grab_at(i: int) -> bool:
        return bool(cap.set(cv2.CAP_PROP_POS_FRAMES, i)) and cap.grab()

    bad, step = failed, 1
    while True:
        good = bad + step
        if good >= n_declared:
            good = n_declared - 1
            if good <= bad or not grab_at(good):
                return None
            break
        if grab_at(good):
            break
        bad, step = good, step * 2
    while good - bad > 1:
        mid = (bad + good) // 2
        if grab_at(mid):
            good = mid
        else:
            bad = mid
    return good if grab_at(good) else None


def skipped_frames_note(frames: list[int]) -> str:
    """The warning for frames that a video could not give (corrupt or missing)."""
    return (f"{len(frames)} corrupt or missing video frame(s) skipped (first {frames[0]}, "
            f"last {frames[-1]}); boxes there are the tracker's predictions")



def read_frames(video: Path, indices: list[int]) -> dict[int, np.ndarray]:
    """Decode only the requested frames (0-based) of a video file or image folder.

    A video is streamed once in order: frames between the wanted ones are grabbed (not
    converted), long gaps are skipped by seeking. Missing frames are left out of the result.
    """
    video = Path(video)
    wanted = sorted({int(i) for i in indices if i is not None and i >= 0})
    out: dict[int, np.ndarray] = {}
    if not wanted:
        return out
    if video.is_dir():
        files = image_files(video)
        for i in wanted:
            if i < len(files):
                img = cv2.imread(str(files[i]), cv2.IMREAD_COLOR)
                if img is not None:
                    out[i] = img
        return out
    if not video.exists():
        raise MissingInputError(video, "no such video file")
    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise FormatError(video, "OpenCV cannot open this video", "convert it to mp4 with ffmpeg")
    try:
        pos = 0
        for i in wanted:
            if i - pos > 300:
                # Seeking costs a keyframe decode; worth it only over long gaps.
                cap.set(cv2.CAP_PROP_POS_FRAMES, i)
                pos = i
            while pos < i and cap.grab():
                pos += 1
            if pos != i:
                break
            ok, img = cap.read()
            if not ok:
                break
            pos += 1
            out[i] = img
    finally:
        cap.release()
    return out


def video_size_and_fps(video: Path) -> tuple[int, int, float | None]:
    """(width, height) [px] of the first frame and the container frame rate (None for a
    folder or where the container does not say)."""
    video = Path(video)
    if video.is_dir():
        img = cv2.imread(str(image_files(video)[0]), cv2.IMREAD_COLOR)
        if img is None:
            raise FormatError(video, "cannot read the first image of the folder")
        return img.shape[1], img.shape[0], None
    if not video.exists():
        raise MissingInputError(video, "no such video file")
    cap = cv2.VideoCapture(str(video))
    try:
        if not cap.isOpened():
            raise FormatError(
                video, "OpenCV cannot open this video", "convert it to mp4 with ffmpeg")
        w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        fps = float(cap.get(cv2.CAP_PROP_FPS))
    finally:
        cap.release()
    return w, h, fps if math.isfinite(fps) and fps > 0 else None
