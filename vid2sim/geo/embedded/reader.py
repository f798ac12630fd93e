"""Find the telemetry of a recording and read its GPS fixes onto the video clock."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from vid2sim.base.errors import FormatError
from vid2sim.base.fileio import check_input_size
from vid2sim.core.container import Packet, probe_container, stream_packets
from vid2sim.core.records import GpsFix, GpsTrace
from vid2sim.geo.embedded.clock import ClockedFix, on_video_clock
from vid2sim.geo.embedded.cuetext import parse_cue
from vid2sim.geo.embedded.gpmf import GpmfError, payload_gps
from vid2sim.geo.embedded.mp4boxes import read_box, stamped_lines, telemetry_boxes
from vid2sim.geo.gpsfile import MAX_GPS_BYTES, UERE_M
from vid2sim.geo.nmea import parse_nmea_lines

#: Kinds of telemetry track, as :class:`TelemetryTrack` names them.
GPMF, NMEA_TRACK, NMEA_BOX, CUES = "gpmf", "nmea-track", "nmea-box", "subtitle-telemetry"
#: Packets of a track looked at to tell what it holds (a track may start without a fix).
SNIFF_PACKETS = 5
_NMEA = re.compile(r"\$[A-Z]{2}(RMC|GGA),")
_TEXT_CODECS = frozenset({"mov_text", "subrip", "srt", "ass", "ssa", "text", "webvtt"})


@dataclass(frozen=True, slots=True)
class TelemetryTrack:
    """A telemetry source inside a recording.

    :param kind: ``gpmf``, ``nmea-track``, ``nmea-box`` or ``subtitle-telemetry``
    :param stream: the container's stream index (None for a box)
    :param label: what a person reads in ``vid2sim probe`` (handler, codec or box)
    :param n_packets: packets (or lines) in the track
    """

    kind: str
    stream: int | None
    label: str
    n_packets: int


def find_telemetry(path: Path) -> list[TelemetryTrack]:
    """The GPS-bearing telemetry tracks and boxes of a recording, best first (GPMF, NMEA,
    cues), from the first packets of each non-video track and the file's boxes.

    Raises
    ------
    FormatError
        The container cannot be read or a box is truncated.
    """
    path = Path(path)
    info = probe_container(path)
    found: list[TelemetryTrack] = []
    for s in info.streams:
        if s.kind not in ("data", "subtitle"):
            continue
        kind = _sniff(_first_packets(path, s.index), s.codec)
        if kind is not None:
            found.append(TelemetryTrack(kind, s.index, s.handler or s.codec or s.kind,
                                        s.n_packets))
    if info.format.startswith("mov"):
        for box in telemetry_boxes(path):
            found.append(TelemetryTrack(NMEA_BOX, None, f"'{box.type.strip()}' box at byte "
                                        f"{box.offset}", box.size))
    order = {GPMF: 0, NMEA_TRACK: 1, NMEA_BOX: 2, CUES: 3}
    return sorted(found, key=lambda t: order[t.kind])


def _first_packets(path: Path, index: int) -> list[Packet]:
    out = []
    for packet in stream_packets(path, index):
        out.append(packet)
        if len(out) >= SNIFF_PACKETS:
            break
    return out


def _sniff(packets: list[Packet], codec: str) -> str | None:
    for p in packets:
        if p.data.startswith(b"DEVC"):
            return GPMF
        text = packet_text(p, codec)
        if _NMEA.search(text):
            return NMEA_TRACK
        if parse_cue(text) is not None:
            return CUES
    return None


def packet_text(packet: Packet, codec: str) -> str:
    """A text packet's text: ``mov_text`` (3GPP timed text, 3GPP TS 26.245 section 5.17)
    samples start with a 16-bit length; other text codecs are the text itself."""
    data = packet.data
    if codec == "mov_text" and len(data) >= 2:
        n = int.from_bytes(data[:2], "big")
        data = data[2:2 + n]
    return data.decode("utf-8", errors="replace")


# --------------------------------------------------------------------------- read


def read_embedded(path: Path) -> GpsTrace:
    """The GPS fixes inside a recording, on its video clock (the best track of
    :func:`find_telemetry`).

    Raises
    ------
    FormatError
        No telemetry track with GPS, a track without a fix, a broken GPMF payload, a
        truncated container.
    """
    path = Path(path)
    tracks = find_telemetry(path)
    if not tracks:
        raise FormatError(path, "the video holds no GPS telemetry track (GoPro GPMF, NMEA or "
                          "subtitle telemetry)", "give the GPS log with --gps FILE")
    track = tracks[0]
    if track.kind == GPMF:
        return _read_gpmf(path, track.stream)
    if track.kind == NMEA_TRACK:
        return _read_nmea_track(path, track.stream)
    if track.kind == NMEA_BOX:
        return _read_nmea_box(path)
    return _read_cues(path, track.stream, "subtitle-telemetry")


def read_cue_file(path: Path) -> GpsTrace:
    """A sidecar ``.SRT`` of telemetry cues (DJI, dash-cams), read by FFmpeg's SRT demuxer:
    each cue's start is its fix's video time."""
    check_input_size(Path(path), MAX_GPS_BYTES, "GPS")
    return _read_cues(Path(path), 0, "srt")


def _read_gpmf(path: Path, stream: int) -> GpsTrace:
    clocked: list[ClockedFix] = []
    anchors: list[float] = []
    n_no_fix = n_broken = 0
    for packet in stream_packets(path, stream):
        try:
            streams = payload_gps(packet.data)
        except GpmfError:
            n_broken += 1
            continue
        for gps in streams:
            if gps.kind == "GPS5" and gps.fix is not None and gps.fix < 2:
                n_no_fix += len(gps.rows)
                continue
            n_no_fix += gps.n_no_fix
            step = packet.duration_s / len(gps.rows) if gps.rows else 0.0
            if gps.utc_s is not None:
                anchors.append(gps.utc_s - packet.t_s)
            for i, (lat, lon, alt, speed, utc, dop) in enumerate(gps.rows):
                fix = GpsFix(t_utc_s=0.0, lat_deg=lat, lon_deg=lon, alt_m=alt,
                             speed_mps=speed if speed >= 0 else None,
                             accuracy_m=None if dop is None or dop >= 99 else dop * UERE_M)
                clocked.append(ClockedFix(fix, packet.t_s + i * step, utc))
    warnings = [f"skipped {n_broken} GPMF payloads that break the KLV layout"] if n_broken else []
    if n_broken and not clocked:
        raise FormatError(path, f"all {n_broken} GPMF payloads with data break the KLV layout",
                          "the telemetry track is damaged")
    return on_video_clock(clocked, "gpmf", path, anchors_s=anchors, n_skipped=n_no_fix,
                          warnings=warnings)


def _nmea_on_clock(path: Path, fmt: str, lines: list[str], line_t_s: list[float | None],
                   ) -> GpsTrace:
    parsed = parse_nmea_lines(lines)
    clocked = [ClockedFix(fix, line_t_s[line], fix.t_utc_s)
               for fix, line in zip(parsed.fixes, parsed.lines, strict=True)
               if line_t_s[line] is not None]
    return on_video_clock(clocked, fmt, path, n_skipped=parsed.n_bad + parsed.n_void,
                          warnings=parsed.warnings)


def _read_nmea_track(path: Path, stream: int) -> GpsTrace:
    codec = next(s.codec for s in probe_container(path).streams if s.index == stream)
    lines: list[str] = []
    times: list[float | None] = []
    for packet in stream_packets(path, stream):
        for line in packet_text(packet, codec).splitlines():
            lines.append(line)
            times.append(packet.t_s)
    return _nmea_on_clock(path, "nmea-track", lines, times)


def _read_nmea_box(path: Path) -> GpsTrace:
    lines: list[str] = []
    stamps: list[float | None] = []
    for box in telemetry_boxes(path):
        more_lines, more_stamps = stamped_lines(read_box(path, box))
        lines += more_lines
        stamps += more_stamps
    first = next((s for s in stamps if s is not None), None)
    if first is None:
        raise FormatError(path, "the NMEA box has no camera time stamps", "is it a BlackVue file?")
    # The box has no packet times: the camera stamps are its clock, the first taken as the
    # first frame (the camera starts both together).
    times = [None if s is None else s - first for s in stamps]
    trace = _nmea_on_clock(path, "nmea-box", lines, times)
    trace.warnings.append("NMEA box: the first camera time stamp is taken as the first frame "
                          "(the box has no per-frame clock)")
    return trace


def _read_cues(path: Path, stream: int, fmt: str) -> GpsTrace:
    info = probe_container(path)
    codec = next((s.codec for s in info.streams if s.index == stream), "")
    clocked: list[ClockedFix] = []
    anchors: list[float] = []
    n_no_fix = 0
    for packet in stream_packets(path, stream):
        cue = parse_cue(packet_text(packet, codec))
        if cue is None:
            n_no_fix += 1
            continue
        fix = GpsFix(t_utc_s=0.0, lat_deg=cue.lat_deg, lon_deg=cue.lon_deg, alt_m=cue.alt_m,
                     speed_mps=cue.speed_mps)
        clocked.append(ClockedFix(fix, packet.t_s))
        if cue.clock_s is not None:
            anchors.append(cue.clock_s - packet.t_s)
    return on_video_clock(clocked, fmt, path, anchors_s=anchors, n_skipped=n_no_fix)
