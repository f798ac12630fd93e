"""What a video file or folder of images is, and random access to its frames.

One frame numbering for every stage: a folder's images in name order (``.png``, ``.jpg``,
``.jpeg``), a video's frames in decoding order. :mod:`vid2sim.detect.video` streams frames
with this numbering; evaluation reads single keyframes with it.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from vid2sim.defaults import IMAGE_FOLDER_FPS
from vid2sim.errors import InputError
from vid2sim.records import VideoInfo

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def image_files(folder: Path) -> list[Path]:
    """The images of a folder used as a video, in name order (frame i is the i-th)."""
    files = sorted(p for p in folder.iterdir()
                   if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise InputError(folder, "folder holds no .png/.jpg images",
                         "give a video file or a folder of frames named in time order")
    return files


def open_capture(path: Path) -> cv2.VideoCapture:
    """An opened OpenCV capture, or an input error naming the file."""
    if not path.exists():
        raise InputError(path, "no such video file or folder")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        cap.release()
        raise InputError(path, "OpenCV cannot open this video",
                         "check the file is a complete video (mp4/avi/mov) or convert it with ffmpeg")
    return cap


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
        first = cv2.imread(str(files[0]), cv2.IMREAD_COLOR)
        if first is None:
            raise InputError(files[0], "cannot read this image")
        return VideoInfo(width=first.shape[1], height=first.shape[0],
                         fps=float(fps or IMAGE_FOLDER_FPS), n_frames=len(files))
    cap = open_capture(path)
    try:
        rate = cap.get(cv2.CAP_PROP_FPS)
        rate = float(fps) if fps else (rate if rate and np.isfinite(rate) and rate > 0 else 0.0)
        if rate <= 0:
            raise InputError(path, "video declares no frame rate", "pass the frame rate explicitly")
        return VideoInfo(width=int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)),
                         height=int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)),
                         fps=rate, n_frames=int(cap.get(cv2.CAP_PROP_FRAME_COUNT)))
    finally:
        cap.release()



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
        raise InputError(video, "no such video file")
    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise InputError(video, "OpenCV cannot open this video", "convert it to mp4 with ffmpeg")
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
            raise InputError(video, "cannot read the first image of the folder")
        return img.shape[1], img.shape[0], None
    if not video.exists():
        raise InputError(video, "no such video file")
    cap = cv2.VideoCapture(str(video))
    try:
        if not cap.isOpened():
            raise InputError(video, "OpenCV cannot open this video", "convert it to mp4 with ffmpeg")
        w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        fps = float(cap.get(cv2.CAP_PROP_FPS))
    finally:
        cap.release()
    return w, h, fps if math.isfinite(fps) and fps > 0 else None
