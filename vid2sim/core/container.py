"""What a video container holds and its clock, read with PyAV (FFmpeg's demuxers).

The frames themselves are decoded through OpenCV (:mod:`vid2sim.core.videofile`); this module
reads what OpenCV does not show: the streams beside the video (telemetry in data and subtitle
tracks), their packets with presentation times, the video's codec, rotation and frame
timing from the container's index, and the recording's start time.

One clock: **video time** [s] is a packet's presentation time minus that of the video
stream's first frame (``stream.start_time``), the same zero as the frames' ``t_s`` of
:func:`vid2sim.detect.video.iter_frames` (OpenCV's ``CAP_PROP_POS_MSEC`` from the first
frame). Telemetry packets are put on that clock here, so their fixes need no offset guessing.

PyAV is imported where it is used: the video-only commands do not load it unless a file is
probed.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from vid2sim.base.errors import FormatError, MissingInputError

#: First bytes of the containers probed for telemetry: ISO BMFF/QuickTime (``ftyp`` at byte
#: 4, ISO/IEC 14496-12 4.3; older QuickTime files start with ``moov``/``mdat``/``wide``/
#: ``free``), Matroska/WebM (EBML magic 1A 45 DF A3), AVI (RIFF .... AVI).
ISO_BMFF_FIRST_BOXES = (b"ftyp", b"moov", b"mdat", b"wide", b"free", b"skip")
EBML_MAGIC = b"\x1a\x45\xdf\xa3"

#: Two frame intervals differing by more than this fraction make a variable frame rate
#: (a 30 fps clip on a 90 kHz clock has intervals 3003 +- 1 ticks: 0.03 %).
VFR_TOLERANCE = 0.01
#: The codec name of a video track whose sample entry FFmpeg does not know.
UNKNOWN_CODEC = "unknown"


def looks_like_container(head: bytes) -> bool:
    """True when the first bytes of a file are those of a video container (not a text log)."""
    if len(head) >= 8 and head[4:8] in ISO_BMFF_FIRST_BOXES:
        return True
    if head.startswith(EBML_MAGIC):
        return True
    return head[:4] == b"RIFF" and head[8:12] == b"AVI "


@dataclass(frozen=True, slots=True)
class StreamInfo:
    """One stream of a container.

    :param kind: "video", "audio", "subtitle", "data" or "attachment"
    :param codec: decoder name ("h264", "hevc", "mov_text"); "" for data tracks without one
    :param handler: the track's handler name (QuickTime ``hdlr``, e.g. "GoPro MET")
    :param n_packets: packets in the container's index (0 if it has none)
    :param duration_s: the stream's duration [s], None if the container does not say
    """

    index: int
    kind: str
    codec: str
    handler: str
    n_packets: int
    duration_s: float | None


@dataclass(frozen=True, slots=True)
class VideoStreamInfo:
    """The video stream: codec, size as shown (after rotation), rotation and frame timing.

    :param width, height: frame size [px] as displayed (rotation applied)
    :param rotation_deg: counter-clockwise display rotation of the stored pixels [deg]
        (the display matrix); 0, 90, 180 or 270
    :param nominal_fps: the container's average frame rate [frames/s]
    :param interval_s: (min, median, max) interval between frames [s] from the index
    :param n_frames: frames in the index (or declared)
    :param start_s: presentation time of the first frame on the container clock [s]
    :param time_base_s: the stream's clock tick [s] (1/90000 for most MP4s)
    :param span_s: time from the first to the last frame [s] from the index, None without one
    """

    index: int
    codec: str
    width: int
    height: int
    rotation_deg: int
    nominal_fps: float
    interval_s: tuple[float, float, float] | None
    n_frames: int
    start_s: float
    time_base_s: float
    span_s: float | None = None

    @property
    def variable_rate(self) -> bool:
        """Whether the frame intervals differ (variable frame rate or dropped frames)."""
        if self.interval_s is None:
            return False
        lo, med, hi = self.interval_s
        return med > 0 and (hi - lo) / med > VFR_TOLERANCE


@dataclass(frozen=True, slots=True)
class ContainerInfo:
    """What a container holds.

    :param creation_utc_s: the recording's creation time (``creation_time`` tag) [s since the
        epoch]; cameras often write local time labelled UTC, so it orders segments of one
        camera but is no GPS clock
    """

    path: Path
    format: str
    duration_s: float | None
    creation_utc_s: float | None
    video: VideoStreamInfo | None
    streams: tuple[StreamInfo, ...] = field(default_factory=tuple)


@dataclass(frozen=True, slots=True)
class Packet:
    """One packet of a non-video stream on the video clock: ``t_s`` [s] from the first frame,
    ``duration_s`` [s] (0 where the container gives none), the raw bytes."""

    t_s: float
    duration_s: float
    data: bytes


def _open(path: Path):
    import av  # FFmpeg's demuxers: loaded only when a container is probed

    path = Path(path)
    if not path.is_file():
        raise MissingInputError(path, "no such video file")
    try:
        return av.open(str(path), metadata_errors="ignore")
    except av.error.FFmpegError as exc:
        raise FormatError(path, f"not a readable video container ({_ffmpeg_reason(exc)})",
                          "a truncated recording lacks its index (moov atom); is the file "
                          "complete?") from None


def _ffmpeg_reason(exc: Exception) -> str:
    text = getattr(exc, "strerror", None) or str(exc)
    return str(text).split(":")[0].strip() or type(exc).__name__


def probe_container(path: Path) -> ContainerInfo:
    """The streams, video timing and start time of a container (no frame decoded except the
    first, for its rotation).

    Raises
    ------
    MissingInputError
        The file is not there.
    FormatError
        FFmpeg cannot read the container (truncated, not a video).
    """
    path = Path(path)
    with _open(path) as container:
        streams = tuple(_stream_info(s) for s in container.streams)
        video = None
        if container.streams.video:
            video = _video_info(container, container.streams.video[0])
        duration = container.duration / 1e6 if container.duration else None
        return ContainerInfo(path=path, format=container.format.name, duration_s=duration,
                             creation_utc_s=_creation_time(container.metadata),
                             video=video, streams=streams)


def _stream_info(stream) -> StreamInfo:
    ctx = stream.codec_context
    codec = ctx.name if ctx is not None else ""
    handler = str(stream.metadata.get("handler_name", "")).strip().strip("\x00").strip()
    # QuickTime handler names are Pascal strings: FFmpeg may keep the length byte
    handler = handler.lstrip("".join(chr(c) for c in range(32)))
    tb = float(stream.time_base) if stream.time_base else 0.0
    duration = stream.duration * tb if stream.duration and tb else None
    try:
        n_packets = len(stream.index_entries)
    except (AttributeError, TypeError):
        n_packets = 0
    return StreamInfo(index=stream.index, kind=stream.type, codec=codec or "",
                      handler=handler, n_packets=n_packets or int(stream.frames or 0),
                      duration_s=duration)


def _video_info(container, stream) -> VideoStreamInfo:
    ctx = stream.codec_context
    tb = float(stream.time_base) if stream.time_base else 0.0
    times = _index_times(stream, tb)
    interval = None
    if len(times) > 2:
        d = np.diff(times)
        d = d[d > 0]
        if len(d):
            interval = (float(d.min()), float(np.median(d)), float(d.max()))
    rate = float(stream.average_rate) if stream.average_rate else 0.0
    if not (math.isfinite(rate) and rate > 0) and interval is not None:
        rate = 1.0 / interval[1]
    if ctx is None:  # a codec FFmpeg does not know: no decoder, no frame size
        return VideoStreamInfo(index=stream.index, codec=UNKNOWN_CODEC, width=0, height=0,
                               rotation_deg=0, nominal_fps=rate, interval_s=interval,
                               n_frames=len(times), start_s=0.0, time_base_s=tb)
    rotation = _rotation(container, stream)
    width, height = int(ctx.width), int(ctx.height)
    if rotation % 180:
        width, height = height, width
    start = stream.start_time * tb if stream.start_time is not None and tb else 0.0
    return VideoStreamInfo(index=stream.index, codec=ctx.name, width=width, height=height,
                           rotation_deg=rotation, nominal_fps=rate, interval_s=interval,
                           n_frames=len(times) or int(stream.frames or 0), start_s=start,
                           time_base_s=tb,
                           span_s=float(times[-1] - times[0]) if len(times) > 1 else None)


def _index_times(stream, tb: float) -> np.ndarray:
    """The frames' times [s] from the container index (decode order; sorted)."""
    try:
        entries = stream.index_entries
        ticks = np.array([e.timestamp for e in entries], dtype=float)
    except (AttributeError, TypeError):
        ticks = np.zeros(0)
    return np.sort(ticks) * tb


def _rotation(container, stream) -> int:
    """The display rotation [deg, counter-clockwise, 0/90/180/270] of the first frame."""
    import av

    try:
        frame = next(container.decode(stream))
    except (StopIteration, av.error.FFmpegError, ValueError):
        return 0
    finally:
        container.seek(0)
    rot = round(float(getattr(frame, "rotation", 0) or 0))
    return rot % 360 if rot % 90 == 0 else 0


def _creation_time(metadata) -> float | None:
    text = metadata.get("creation_time") if metadata else None
    if not text:
        return None
    try:
        when = datetime.fromisoformat(str(text))
    except ValueError:
        return None
    return (when if when.tzinfo else when.replace(tzinfo=UTC)).timestamp()


def stream_packets(path: Path, stream_index: int) -> Iterator[Packet]:
    """The packets of one stream in file order, on the video clock.

    Raises
    ------
    FormatError
        The container cannot be read, or breaks off inside the stream's packets.
    """
    import av

    path = Path(path)
    with _open(path) as container:
        video_start = 0.0
        if container.streams.video:
            v = container.streams.video[0]
            if v.start_time is not None and v.time_base:
                video_start = float(v.start_time * v.time_base)
        stream = container.streams[stream_index]
        try:
            for packet in container.demux(stream):
                if packet.pts is None or packet.size == 0:
                    continue  # the demuxer's flush packet, empty subtitle samples
                tb = float(packet.time_base or stream.time_base)
                yield Packet(t_s=float(packet.pts) * tb - video_start,
                             duration_s=float(packet.duration or 0) * tb, data=bytes(packet))
        except av.error.FFmpegError as exc:
            raise FormatError(path, f"the container breaks off in stream {stream_index} "
                              f"({_ffmpeg_reason(exc)})", "is the file truncated?") from None


def codec_of(path: Path) -> str | None:
    """The video codec FFmpeg names for a file (:data:`UNKNOWN_CODEC` for a sample entry
    FFmpeg does not know), or None where the file cannot be probed."""
    import av

    try:
        with av.open(str(path), metadata_errors="ignore") as container:
            if not container.streams.video:
                return None
            ctx = container.streams.video[0].codec_context
            name = ctx.name if ctx is not None else ""
            return name if name and name != "none" else UNKNOWN_CODEC
    except (av.error.FFmpegError, OSError, ValueError):
        return None
