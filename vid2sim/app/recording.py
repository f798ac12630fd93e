"""What a recording brings besides its frames: its clock, and the GPS inside it.

A dash-cam or GoPro file carries its GPS track (:mod:`vid2sim.geo.embedded`): a build without
``--gps`` uses it, and ``--gps VIDEO`` names it explicitly. The video's clock (container
presentation times, rotation, codec) is recorded in ``scenario.json``'s
``source.options.video_clock`` so a user of the scenario knows what "t" is.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from vid2sim.app.inputs import Inputs
from vid2sim.base.errors import FormatError, InputError
from vid2sim.core.container import ContainerInfo, looks_like_container, probe_container
from vid2sim.core.records import Note, VideoInfo
from vid2sim.geo.embedded import find_telemetry

#: Bytes read to tell a container from an image folder or a text file.
_HEAD_BYTES = 16


def is_container_file(path: Path | None) -> bool:
    """Whether ``path`` is a video container file (not a folder of images, not a text log)."""
    if path is None or not Path(path).is_file():
        return False
    try:
        with open(path, "rb") as fh:
            return looks_like_container(fh.read(_HEAD_BYTES))
    except OSError:
        return False


def with_embedded_gps(inputs: Inputs) -> tuple[Inputs, list[Note]]:
    """``inputs`` with ``gps`` set to the video itself when no GPS is given and the video
    carries a GPS track; notes saying what was found (a damaged container a warning, since
    the frames may still decode)."""
    if inputs.gps is not None or not is_container_file(inputs.video):
        return inputs, []
    try:
        tracks = find_telemetry(Path(inputs.video))
    except InputError as exc:
        return inputs, [Note.warning(f"cannot look for GPS inside the video: {exc}")]
    if not tracks:
        return inputs, []
    best = tracks[0]
    where = f"stream {best.stream}" if best.stream is not None else best.label
    return replace(inputs, gps=Path(inputs.video)), [Note.assumption(
        f"GPS from the video's own {best.kind} telemetry ({where}, {best.label}), timed by the "
        "container's clock")]


def video_clock(video: Path, info: VideoInfo) -> tuple[dict, ContainerInfo | None]:
    """The time base of the frames, as recorded in ``source.options.video_clock``, and the
    container's facts (None for an image folder).

    Raises
    ------
    FormatError
        A video file FFmpeg cannot read (OpenCV may have opened it; the clock is FFmpeg's).
    """
    if not is_container_file(video):
        return {"clock": "frame index / fps", "fps": info.fps}, None
    try:
        c = probe_container(Path(video))
    except FormatError:
        return {"clock": "OpenCV frame positions", "fps": info.fps}, None
    v = c.video
    if v is None:
        return {"clock": "frame index / fps", "fps": info.fps}, c
    clock = {"clock": "container presentation times", "codec": v.codec,
             "time_base": f"1/{round(1 / v.time_base_s)}" if v.time_base_s > 0 else None,
             "nominal_fps": round(v.nominal_fps, 3), "variable_rate": v.variable_rate,
             "rotation_deg": v.rotation_deg}
    if v.interval_s is not None:
        # min, median, max frame interval [ms]
        clock["frame_interval_ms"] = [round(1000 * x, 3) for x in v.interval_s]
    return clock, c


def video_span_s(info: VideoInfo, container: ContainerInfo | None) -> float:
    """Time from the first to the last frame [s]: the container's frame times where it has an
    index (variable frame rates keep their clock), else (frames - 1) / fps."""
    nominal = (info.n_frames - 1) / info.fps if info.n_frames > 1 else 0.0
    if container is None or container.video is None or container.video.span_s is None:
        return nominal
    return container.video.span_s
