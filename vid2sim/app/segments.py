"""Split recordings: the 1-3 minute segments a dash-cam writes of one drive, built as one.

The segments are ordered by their embedded start time (the GPS clock of their telemetry where
every segment has one, else the container's ``creation_time``, else their names), checked to
be one drive (one camera: the same codec and frame size; each starting where the previous
ends, within :attr:`SegmentConfig.max_gap_s`), and their video packets are copied (not
re-encoded) into one MP4 whose clock runs on across the cuts. Embedded GPS of each segment
is put on that clock in a BDD100K-style JSON (fixes in ms, ``startTime`` = the first frame).
Both live in a temporary folder beside the output, removed after the build.
"""

from __future__ import annotations

import itertools
import json
import math
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from vid2sim.app.build import BuildResult, build
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import SegmentConfig, Settings
from vid2sim.base.errors import FormatError, InconsistentInputError, MissingInputError
from vid2sim.core.container import ContainerInfo, probe_container
from vid2sim.core.records import GpsTrace, Note
from vid2sim.geo.embedded import find_telemetry, read_embedded

VIDEO_SUFFIXES = (".mp4", ".mov", ".m4v", ".mkv", ".avi", ".ts")


@dataclass(frozen=True, slots=True)
class Segment:
    path: Path
    info: ContainerInfo
    trace: GpsTrace | None
    start_s: float | None
    clock: str


def video_files(folder: Path) -> list[Path]:
    """The video files of a folder (a card's folder of segments), in name order."""
    return sorted(p for p in Path(folder).iterdir()
                  if p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES)


def read_segment(path: Path) -> Segment:
    info = probe_container(path)
    if info.video is None:
        raise FormatError(path, "no video stream", "give the recording's video files")
    trace = read_embedded(path) if find_telemetry(path) else None
    if trace is not None and trace.video_start_utc_s:
        return Segment(path, info, trace, trace.video_start_utc_s, "GPS")
    return Segment(path, info, trace, info.creation_utc_s,
                   "creation_time" if info.creation_utc_s is not None else "name")


def order_segments(segments: list[Segment], config: SegmentConfig | None = None
                   ) -> tuple[list[Segment], list[float], list[Note]]:
    """The segments in drive order with each one's offset on the joined clock [s].

    Raises
    ------
    InconsistentInputError
        Segments of different cameras (codec, frame size) or of different drives (a gap
        or an overlap beyond :class:`SegmentConfig`'s bounds).
    """
    config = config or SegmentConfig()
    first = segments[0]
    for s in segments[1:]:
        a, b = first.info.video, s.info.video
        if (a.codec, a.width, a.height) != (b.codec, b.width, b.height):
            raise InconsistentInputError(s.path, f"segment is {b.codec} {b.width}x{b.height}, "
                                         f"{first.path.name} is {a.codec} {a.width}x{a.height}",
                                         "segments of one drive come from one camera")
    clocks = {s.clock for s in segments}
    notes: list[Note] = []
    if "name" in clocks or len(clocks) > 1:
        ordered = sorted(segments, key=lambda s: s.path.name)
        notes.append(Note.warning("segments ordered by file name (no common embedded start "
                                  "time); their gaps are not checked"))
        return ordered, _cumulative(ordered), notes
    ordered = sorted(segments, key=lambda s: s.start_s)
    for prev, nxt in itertools.pairwise(ordered):
        end = prev.start_s + _length(prev)
        gap = nxt.start_s - end
        if gap > config.max_gap_s or gap < -config.max_overlap_s:
            raise InconsistentInputError(
                nxt.path, f"starts {gap:+.1f} s after {prev.path.name} ends ({nxt.clock} "
                "clock): not the next segment of one drive",
                f"give consecutive segments of one recording (gaps up to {config.max_gap_s:g} s)")
    offsets = [0.0]
    for prev, nxt in itertools.pairwise(ordered):
        end = offsets[-1] + _length(prev)
        precise = nxt.clock == "GPS"
        offsets.append(max(end, nxt.start_s - ordered[0].start_s) if precise else end)
    notes.append(Note.assumption(f"{len(ordered)} segments joined as one drive, ordered by "
                                 f"their {ordered[0].clock} start times: "
                                 + ", ".join(s.path.name for s in ordered)))
    return ordered, offsets, notes


def _length(s: Segment) -> float:
    """A segment's length on the video clock [s]: first frame to last plus one interval."""
    v = s.info.video
    interval = v.interval_s[1] if v.interval_s else (1.0 / v.nominal_fps if v.nominal_fps else 0.0)
    span = v.span_s if v.span_s is not None else (s.info.duration_s or 0.0) - interval
    return span + interval


def _cumulative(ordered: list[Segment]) -> list[float]:
    out = [0.0]
    for s in ordered[:-1]:
        out.append(out[-1] + _length(s))
    return out


def join_videos(ordered: list[Segment], offsets: list[float], dst: Path) -> Path:
    """The segments' video packets copied into one MP4, each shifted by its offset."""
    import av

    with av.open(str(dst), "w", format="mp4") as out:
        vout = None
        for seg, offset in zip(ordered, offsets, strict=True):
            with av.open(str(seg.path)) as inp:
                vin = inp.streams.video[0]
                if vout is None:
                    vout = out.add_stream_from_template(vin)
                tb = vin.time_base
                start = vin.start_time or 0
                shift = round(offset / tb) - start
                for pkt in inp.demux(vin):
                    if pkt.dts is None:
                        continue
                    pkt.pts = pkt.pts + shift if pkt.pts is not None else None
                    pkt.dts += shift
                    pkt.time_base = tb
                    pkt.stream = vout
                    out.mux(pkt)
    return dst


def joined_gps(ordered: list[Segment], offsets: list[float], dst: Path) -> Path | None:
    """The segments' embedded fixes on the joined clock, as BDD100K-style JSON (ms since
    the epoch, ``startTime`` = the joined video's first frame); None if no segment has GPS."""
    if not any(s.trace is not None for s in ordered):
        return None
    base = next(s.trace.video_start_utc_s for s in ordered if s.trace is not None) \
        - offsets[next(i for i, s in enumerate(ordered) if s.trace is not None)]
    locations = []
    for seg, offset in zip(ordered, offsets, strict=True):
        if seg.trace is None:
            continue
        for f in seg.trace.fixes:
            t = base + offset + (f.t_utc_s - seg.trace.video_start_utc_s)
            loc = {"timestamp": round(t * 1000, 3), "latitude": f.lat_deg, "longitude": f.lon_deg}
            for key, value in (("altitude", f.alt_m), ("speed", f.speed_mps),
                               ("course", f.course_deg), ("accuracy", f.accuracy_m)):
                if value is not None and math.isfinite(value):
                    loc[key] = value
            locations.append(loc)
    dst.write_text(json.dumps({"startTime": round(base * 1000, 3), "locations": locations}))
    return dst


def segment_list(videos: list[Path]) -> list[Path]:
    """The segments named on the command line: files, or one folder of video files."""
    if len(videos) == 1 and Path(videos[0]).is_dir():
        files = video_files(videos[0])
        return files if files else [Path(videos[0])]  # no videos: a folder of images
    return [Path(v) for v in videos]


def build_drive(videos: list[Path], inputs: Inputs, out_dir: Path,
                settings: Settings | None = None,
                report: Callable[[str], None] | None = None) -> BuildResult:
    """``vid2sim build SEG1 SEG2 ...``: one scenario of consecutive segments (or of the video
    files of one folder); a single video (or an image folder) is built as it is."""
    settings = settings or Settings()
    paths = segment_list(videos)
    if len(paths) == 1:
        return build(replace(inputs, video=paths[0]), out_dir, settings, report=report)
    for p in paths:
        if not p.is_file():
            raise MissingInputError(p, "no such video file", "give the segments' video files")
    ordered, offsets, notes = order_segments([read_segment(p) for p in paths],
                                             settings.segments)
    parent = Path(out_dir).resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".vid2sim-join.", dir=parent))
    try:
        joined = join_videos(ordered, offsets, work / "joined.mp4")
        gps = inputs.gps
        if gps is None:
            gps = joined_gps(ordered, offsets, work / "joined_gps.json")
        return build(replace(inputs, video=joined, gps=gps), out_dir, settings, report=report,
                     extra_notes=notes)
    finally:
        shutil.rmtree(work, ignore_errors=True)
