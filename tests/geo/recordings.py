"""Writers of recordings with GPS inside, built from the published format descriptions.

- GPMF payloads: GoPro gpmf-parser README ("KLV Design": FourCC, type char, structure size,
  16-bit repeat, big-endian data padded to 32 bits; GPS5 int32 lat/lon/alt/2D/3D speed over
  SCAL; GPSU ``yymmddhhmmss.sss``; GPSF; GPSP; GPS9 ``TYPE lllllllSS``). FFmpeg's MP4 muxer
  writes a ``bin_data`` data stream as a ``gpmd`` track with the handler "GoPro MET", as a
  GoPro camera does.
- NMEA 0183 sentences (``$GPRMC``, ``$GPGGA`` with the XOR checksum) in a ``mov_text``
  subtitle track: 3GPP TS 26.245 timed text samples (16-bit length + UTF-8 text).
- BlackVue's ``gps `` box: NMEA lines prefixed ``[ms since the epoch]`` inside a top-level
  ``free`` box (ISO/IEC 14496-12 box = 32-bit size + type).
- Subtitle telemetry: DJI's ``[latitude: ...] [longitude: ...]`` cues.
"""

from __future__ import annotations

import struct
from datetime import UTC, datetime
from fractions import Fraction
from pathlib import Path

from vid2sim.core.records import GpsFix

MS = Fraction(1, 1000)


def klv(key: str, type_char: str, size: int, repeat: int, data: bytes) -> bytes:
    """One GPMF KLV: header + data padded to a multiple of 4 bytes."""
    head = key.encode("latin-1") + bytes([0 if type_char == "" else ord(type_char), size]) \
        + repeat.to_bytes(2, "big")
    return head + data + b"\x00" * (-len(data) % 4)


def nest(key: str, *items: bytes) -> bytes:
    body = b"".join(items)
    return klv(key, "", 4, len(body) // 4, body)


def gpsu_text(t_utc_s: float) -> str:
    dt = datetime.fromtimestamp(t_utc_s, UTC)
    return dt.strftime("%y%m%d%H%M%S") + f".{round((t_utc_s % 1) * 1000) % 1000:03d}"


def gps5_payload(fixes: list[GpsFix], fix_type: int = 3, gpsu: float | None = None,
                 dop: float = 1.5) -> bytes:
    """A payload of one DEVC/STRM with GPS5 samples (SCAL 1e7, 1e7, 1000, 1000, 100)."""
    scal = (10_000_000, 10_000_000, 1000, 1000, 100)
    rows = b"".join(struct.pack(">5i", round(f.lat_deg * scal[0]), round(f.lon_deg * scal[1]),
                                round((f.alt_m or 0.0) * scal[2]),
                                round((f.speed_mps or 0.0) * scal[3]),
                                round((f.speed_mps or 0.0) * scal[4])) for f in fixes)
    items = [klv("STNM", "c", 1, 9, b"GPS (Lat."),
             klv("GPSF", "L", 4, 1, struct.pack(">I", fix_type)),
             klv("GPSU", "U", 16, 1, gpsu_text(gpsu if gpsu is not None else fixes[0].t_utc_s
                                               ).encode()),
             klv("GPSP", "S", 2, 1, struct.pack(">H", round(dop * 100))),
             klv("SCAL", "l", 4, 5, struct.pack(">5i", *scal)),
             klv("GPS5", "l", 20, len(fixes), rows)]
    return nest("DEVC", klv("DVID", "L", 4, 1, b"\x00\x00\x00\x01"),
                klv("DVNM", "c", 1, 6, b"Camera"), nest("STRM", *items))


def gps9_payload(fixes: list[GpsFix], fix_type: int = 3, dop: float = 1.5) -> bytes:
    """A payload with GPS9 samples (TYPE lllllllSS, SCAL per field)."""
    scal = (10_000_000, 10_000_000, 1000, 1000, 100, 1, 1000, 100, 1)
    epoch = datetime(2000, 1, 1, tzinfo=UTC).timestamp()
    rows = b""
    for f in fixes:
        days, secs = divmod(f.t_utc_s - epoch, 86400.0)
        rows += struct.pack(">7i2H", round(f.lat_deg * scal[0]), round(f.lon_deg * scal[1]),
                            round((f.alt_m or 0.0) * scal[2]),
                            round((f.speed_mps or 0.0) * scal[3]),
                            round((f.speed_mps or 0.0) * scal[4]), int(days),
                            round(secs * scal[6]), round(dop * scal[7]), fix_type)
    items = [klv("STNM", "c", 1, 3, b"GPS"), klv("TYPE", "c", 1, 9, b"lllllllSS"),
             klv("SCAL", "l", 4, 9, struct.pack(">9i", *scal)),
             klv("GPS9", "?", 32, len(fixes), rows)]
    return nest("DEVC", klv("DVID", "L", 4, 1, b"\x00\x00\x00\x01"), nest("STRM", *items))


def _checksummed(body: str) -> str:
    acc = 0
    for ch in body:
        acc ^= ord(ch)
    return f"${body}*{acc:02X}"


def _ddmm(value: float, lat: bool) -> tuple[str, str]:
    hemi = ("N" if value >= 0 else "S") if lat else ("E" if value >= 0 else "W")
    v = abs(value)
    deg = int(v)
    minutes = (v - deg) * 60.0
    return (f"{deg:02d}" if lat else f"{deg:03d}") + f"{minutes:09.6f}", hemi


def nmea_sentences(f: GpsFix) -> list[str]:
    """$GPRMC + $GPGGA of one fix (position to 1e-6 minute, about 2 mm)."""
    dt = datetime.fromtimestamp(f.t_utc_s, UTC)
    tod = dt.strftime("%H%M%S") + f".{round((f.t_utc_s % 1) * 100) % 100:02d}"
    lat, ns = _ddmm(f.lat_deg, True)
    lon, ew = _ddmm(f.lon_deg, False)
    knots = (f.speed_mps or 0.0) / (1852.0 / 3600.0)
    course = f"{f.course_deg:.2f}" if f.course_deg is not None else ""
    rmc = f"GPRMC,{tod},A,{lat},{ns},{lon},{ew},{knots:.4f},{course},{dt:%d%m%y},,,A"
    gga = f"GPGGA,{tod},{lat},{ns},{lon},{ew},1,08,1.0,{(f.alt_m or 0.0):.3f},M,0.0,M,,"
    return [_checksummed(rmc), _checksummed(gga)]


def dji_cue(f: GpsFix) -> str:
    dt = datetime.fromtimestamp(f.t_utc_s, UTC)
    return (f'<font size="28">FrameCnt: 1, DiffTime: 33ms\n{dt:%Y-%m-%d %H:%M:%S}.000\n'
            f"[iso : 100] [latitude: {f.lat_deg:.7f}] [longitude: {f.lon_deg:.7f}] "
            f"[rel_alt: 1.0 abs_alt: {(f.alt_m or 0.0):.3f}] </font>")


def remux_with_telemetry(src: Path, dst: Path, kind: str, packets: list[tuple[float, float, bytes]]
                         ) -> Path:
    """``src``'s video stream copied into ``dst`` (MP4) with a telemetry track of ``kind``
    ("gpmf": a gpmd data track; "text": a mov_text subtitle track) holding ``packets`` of
    (video time [s], duration [s], bytes; text packets are given as their UTF-8 text)."""
    import av

    with av.open(str(src)) as inp, av.open(str(dst), "w", format="mp4") as out:
        vin = inp.streams.video[0]
        vout = out.add_stream_from_template(vin)
        if kind == "gpmf":
            tel = out.add_data_stream("bin_data")
        else:
            tel = out.add_mux_stream("mov_text")
        tel.time_base = MS
        for pkt in inp.demux(vin):
            if pkt.dts is None:
                continue
            pkt.stream = vout
            out.mux(pkt)
        for t_s, dur_s, data in packets:
            if kind != "gpmf":
                data = len(data).to_bytes(2, "big") + data
            p = av.Packet(data)
            p.stream = tel
            p.time_base = MS
            p.pts = p.dts = round(t_s * 1000)
            p.duration = round(dur_s * 1000)
            out.mux(p)
    return dst


def copy_video(src: Path, dst: Path) -> Path:
    """``src``'s video stream alone, remuxed into an MP4 (the same frames and clock)."""
    import av

    with av.open(str(src)) as inp, av.open(str(dst), "w", format="mp4") as out:
        vin = inp.streams.video[0]
        vout = out.add_stream_from_template(vin)
        for pkt in inp.demux(vin):
            if pkt.dts is None:
                continue
            pkt.stream = vout
            out.mux(pkt)
    return dst


def append_blackvue_box(path: Path, fixes: list[GpsFix], start_utc_s: float | None = None
                        ) -> Path:
    """A top-level ``free`` box holding a ``gps `` box of ``[ms]``-stamped NMEA lines (a
    first stamp-only line at ``start_utc_s``, the recording's start, where given)."""
    lines = [] if start_utc_s is None else [f"[{round(start_utc_s * 1000)}]"]
    for f in fixes:
        stamp = f"[{round(f.t_utc_s * 1000)}]"
        lines += [stamp + s for s in nmea_sentences(f)]
    text = ("\n".join(lines) + "\n").encode("ascii")
    gps = (8 + len(text)).to_bytes(4, "big") + b"gps " + text
    free = (8 + len(gps)).to_bytes(4, "big") + b"free" + gps
    with open(path, "ab") as fh:
        fh.write(free)
    return path


def write_csv(path: Path, fixes: list[GpsFix], fields: tuple[str, ...]) -> Path:
    """The fixes as a CSV with a header (t in s since the epoch) and the given extra fields
    (alt, speed, heading) that the embedded format also carries."""
    cols = {"alt": lambda f: f.alt_m, "speed": lambda f: f.speed_mps,
            "heading": lambda f: f.course_deg}
    rows = ["t,lat,lon" + "".join(f",{c}" for c in fields)]
    for f in fixes:
        extra = "".join(f",{cols[c](f):.6f}" if cols[c](f) is not None else "," for c in fields)
        rows.append(f"{f.t_utc_s:.3f},{f.lat_deg:.8f},{f.lon_deg:.8f}{extra}")
    path.write_text("\n".join(rows) + "\n")
    return path
