"""Writing a replay video, one frame at a time (nothing is held but the frame being encoded).

H.264 in MP4 through PyAV (FFmpeg's libx264) where PyAV and the encoder are installed:
what every browser plays, so the HTML report's ``<video>`` element works. Without them,
OpenCV's own writer with MPEG-4 part 2 (``mp4v``): any player and OpenCV decode it, but
browsers do not (the report then says so). Frames are BGR ``uint8`` arrays of one size;
odd sizes are padded by a pixel (4:2:0 chroma needs even sides).
"""

from __future__ import annotations

import logging
from fractions import Fraction
from pathlib import Path
from typing import Self

import cv2
import numpy as np

from vid2sim.base.errors import OutputError
from vid2sim.evaluate.replayconfig import EncoderConfig

log = logging.getLogger(__name__)

H264, MPEG4 = "h264", "mp4v"
CODECS = (H264, MPEG4)


def _pyav():
    """PyAV's module when it and its libx264 encoder are installed, else None."""
    try:
        import av
    except ImportError:
        return None
    try:
        av.codec.Codec("libx264", "w")
    except Exception:  # noqa: BLE001 - any failure means: no usable encoder
        return None
    return av


def best_codec() -> str:
    """:data:`H264` where PyAV can encode it, else :data:`MPEG4`."""
    return H264 if _pyav() is not None else MPEG4


def browser_playable(codec: str) -> bool:
    """True for a codec browsers play inside MP4."""
    return codec == H264


class VideoOut:
    """An MP4 file being written (use as a context manager; :meth:`write` per frame).

    Parameters
    ----------
    path : Path
        The file to write (the caller renames it into place).
    width, height : int
        Frame size [px] (padded to even).
    fps : float
        Frame rate [frames/s].
    codec : str, optional
        :data:`H264` or :data:`MPEG4`; default :func:`best_codec`.
    """

    def __init__(self, path: Path, width: int, height: int, fps: float,
                 codec: str | None = None, config: EncoderConfig | None = None):
        self.path = Path(path)
        self.config = config or EncoderConfig()
        self.codec = codec or best_codec()
        self.size = (int(width) + int(width) % 2, int(height) + int(height) % 2)
        self.fps = float(fps)
        self.frames = 0
        self._container = self._stream = self._cv = None
        if self.codec == H264:
            self._open_pyav()
        elif self.codec == MPEG4:
            self._cv = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"),
                                       self.fps, self.size)
            if not self._cv.isOpened():
                raise OutputError(self.path, "OpenCV cannot write an MP4 video here",
                                  "choose a writable .mp4 path")
        else:
            raise ValueError(f"codec must be one of {CODECS}, got {codec!r}")

    def _open_pyav(self) -> None:
        av = _pyav()
        if av is None:
            raise ValueError("H.264 needs PyAV with FFmpeg's libx264")
        self._container = av.open(str(self.path), mode="w", format="mp4",
                                  options={"movflags": "+faststart"})
        rate = Fraction(self.fps).limit_denominator(1001)
        stream = self._container.add_stream("libx264", rate=rate)
        self._time_base = Fraction(1) / rate
        stream.width, stream.height = self.size
        stream.pix_fmt = "yuv420p"
        stream.options = {"crf": str(self.config.crf), "preset": self.config.preset}
        stream.codec_context.thread_count = max(1, int(self.config.threads))
        self._stream = stream
        self._av = av

    def write(self, frame_bgr: np.ndarray) -> None:
        """Append one frame (BGR uint8; padded or cut to the video's size)."""
        w, h = self.size
        img = frame_bgr
        if img.shape[1] != w or img.shape[0] != h:
            img = cv2.copyMakeBorder(img[:h, :w], 0, max(0, h - img.shape[0]), 0,
                                     max(0, w - img.shape[1]), cv2.BORDER_CONSTANT)
        if self._cv is not None:
            self._cv.write(img)
        else:
            frame = self._av.VideoFrame.from_ndarray(np.ascontiguousarray(img), format="bgr24")
            frame.pts = self.frames
            frame.time_base = self._time_base
            for packet in self._stream.encode(frame):
                self._container.mux(packet)
        self.frames += 1

    def close(self) -> None:
        """Flush the encoder and finish the file."""
        if self._cv is not None:
            self._cv.release()
            self._cv = None
        if self._container is not None:
            try:
                for packet in self._stream.encode():
                    self._container.mux(packet)
            finally:
                self._container.close()
                self._container = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
