"""GoPro GPMF telemetry (the ``gpmd`` track of a GoPro MP4): GPS5 and GPS9 -> GPS fixes.

Format source: GoPro's gpmf-parser README ("GPMF -- GoPro Metadata Format", github.com/gopro/
gpmf-parser, sections "KLV Design", "Alignment and Storage", "GPMF Timing and Clocks" and the
per-camera tables of GPS5/GPS9). What this reader relies on:

- A payload (one MP4 sample of the ``gpmd`` track) is a sequence of KLV triples: a FourCC key
  (4 ASCII bytes), a type char (1 byte; 0 = nested KLV), a structure size (1 byte, bytes per
  sample) and a repeat count (2 bytes, big-endian), then size x repeat bytes of big-endian data
  padded to a multiple of 4 bytes.
- ``DEVC`` (a device) nests ``STRM`` (a stream); inside a stream, ``SCAL`` (divisors), ``TYPE``
  (the field types of a complex ``?`` structure) and ``GPSF``/``GPSU``/``GPSP`` apply to the
  data KLV that follows them in the same nest.
- ``GPS5``: int32 samples (lat, lon, alt, 2D speed, 3D speed) divided by ``SCAL``; deg, deg, m,
  m/s, m/s. ``GPSU`` is the payload's UTC time (``yymmddhhmmss.sss``), ``GPSF`` the fix
  (0 no lock, 2 2D, 3 3D), ``GPSP`` the dilution of precision x 100.
- ``GPS9`` (HERO11 and later): per sample lat, lon, alt, 2D speed, 3D speed, days since
  2000-01-01, seconds since midnight (ms precision), DOP, fix; ``TYPE`` "lllllllSS" and
  ``SCAL`` give the field types and divisors.
- Timing is not in GPMF: a payload's samples span the MP4 sample's duration (stts), which is
  the video's clock.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime

#: Bytes of one value of each GPMF type char (gpmf-parser README, "Type Char" table).
TYPE_SIZES = {"b": 1, "B": 1, "c": 1, "d": 8, "f": 4, "F": 4, "G": 16, "j": 8, "J": 8,
              "l": 4, "L": 4, "q": 4, "Q": 8, "s": 2, "S": 2, "U": 16}
_STRUCT_CHARS = {"b": "b", "B": "B", "d": "d", "f": "f", "j": "q", "J": "Q", "l": "i",
                 "L": "I", "s": "h", "S": "H"}
#: The GPS9 fields (gpmf-parser README, HERO11 table) and their types when no TYPE says.
GPS9_DEFAULT_TYPE = "lllllllSS"
#: GPS9 dates count days from this day.
GPS9_EPOCH = datetime(2000, 1, 1, tzinfo=UTC)


class GpmfError(ValueError):
    """A payload that does not follow the KLV layout (truncated, a size beyond its nest)."""


@dataclass(frozen=True, slots=True)
class Klv:
    """One KLV triple: key, type char ('' for nested), structure size, repeat, raw data."""

    key: str
    type: str
    size: int
    repeat: int
    data: bytes


def iter_klv(buf: bytes) -> Iterator[Klv]:
    """The KLV triples at one nesting level of ``buf`` (a payload or a nested value).

    Raises
    ------
    GpmfError
        A header or value that runs past the end of ``buf``.
    """
    pos, n = 0, len(buf)
    while pos + 8 <= n:
        key_bytes = buf[pos:pos + 4]
        if key_bytes == b"\x00\x00\x00\x00":
            break  # zero padding after the last KLV
        type_byte, size, repeat = buf[pos + 4], buf[pos + 5], int.from_bytes(buf[pos + 6:pos + 8], "big")
        length = size * repeat
        end = pos + 8 + length
        if end > n:
            raise GpmfError(f"{key_bytes!r}: {length} bytes of data but {n - pos - 8} left")
        key = key_bytes.decode("latin-1")
        yield Klv(key, "" if type_byte == 0 else chr(type_byte), size, repeat,
                  bytes(buf[pos + 8:end]))
        pos = pos + 8 + ((length + 3) & ~3)
    if 0 < n - pos < 8 and any(buf[pos:]):
        raise GpmfError(f"{n - pos} stray bytes after the last KLV")


def klv_values(item: Klv, complex_type: str | None = None) -> list[tuple]:
    """The samples of a KLV as tuples of numbers (strings for 'c'/'U'/'F' types).

    ``complex_type`` is the stream's TYPE string for a ``?`` KLV (arrays ``x[n]`` expanded).
    """
    if item.repeat == 0 or item.size == 0:
        return []
    if item.type in ("c", "U"):
        if item.type == "U" or item.size > 1:
            return [(item.data[i * item.size:(i + 1) * item.size].decode("latin-1").rstrip("\x00"),)
                    for i in range(item.repeat)]
        return [(item.data.decode("latin-1").rstrip("\x00"),)]
    if item.type == "F":
        return [tuple(item.data[j:j + 4].decode("latin-1")
                      for j in range(i * item.size, (i + 1) * item.size, 4))
                for i in range(item.repeat)]
    chars = _expand_type(complex_type) if item.type == "?" else None
    if chars is None:
        if item.type not in _STRUCT_CHARS and item.type not in ("q", "Q"):
            raise GpmfError(f"{item.key}: type {item.type!r} is not numeric")
        per = TYPE_SIZES[item.type]
        if item.size % per:
            raise GpmfError(f"{item.key}: structure size {item.size} is not a multiple of {per}")
        chars = item.type * (item.size // per)
    fmt = ">" + "".join(_STRUCT_CHARS.get(c, "i" if c == "q" else "q") for c in chars)
    if struct.calcsize(fmt) != item.size:
        raise GpmfError(f"{item.key}: TYPE {complex_type!r} does not fill {item.size} bytes")
    out = []
    for values in struct.iter_unpack(fmt, item.data[:item.size * item.repeat]):
        out.append(tuple(v / 65536.0 if c == "q" else v / 4294967296.0 if c == "Q" else v
                         for v, c in zip(values, chars, strict=True)))
    return out


def _expand_type(text: str | None) -> str | None:
    """A TYPE string with arrays expanded: ``f[3]L`` -> ``fffL``."""
    if not text:
        return None
    out, i = [], 0
    while i < len(text):
        c = text[i]
        if i + 1 < len(text) and text[i + 1] == "[":
            close = text.find("]", i)
            if close < 0:
                raise GpmfError(f"TYPE {text!r}: unclosed array")
            out.append(c * int(text[i + 2:close]))
            i = close + 1
        else:
            out.append(c)
            i += 1
    expanded = "".join(out)
    if any(c not in _STRUCT_CHARS and c not in ("q", "Q") for c in expanded):
        raise GpmfError(f"TYPE {text!r} holds a non-numeric field")
    return expanded


# --------------------------------------------------------------------------- GPS streams


@dataclass(slots=True)
class GpsSamples:
    """The GPS samples of one payload, before they are put on a clock.

    :param rows: per sample (lat deg, lon deg, alt m, 2D speed m/s, utc s or None, dop or None)
    :param fix: the payload's GPSF (GPS5) or None where each sample carries its own (GPS9)
    :param utc_s: the payload's GPSU time [s since the epoch], None if absent
    :param kind: "GPS5" or "GPS9"
    """

    kind: str
    rows: list[tuple[float, float, float, float, float | None, float | None]] = field(
        default_factory=list)
    fix: int | None = None
    utc_s: float | None = None
    n_no_fix: int = 0


def gpsu_time(text: str) -> float:
    """A GPSU string ``yymmddhhmmss.sss`` (years 20xx) -> seconds since the epoch (UTC)."""
    text = text.strip()
    if len(text) < 12 or not text[:12].isdigit():
        raise GpmfError(f"GPSU {text!r} is not yymmddhhmmss.sss")
    seconds = float(text[10:]) if text[10:] else 0.0
    if not 0.0 <= seconds < 61.0:
        raise GpmfError(f"GPSU {text!r}: seconds out of range")
    try:
        day = datetime(2000 + int(text[0:2]), int(text[2:4]), int(text[4:6]), int(text[6:8]),
                       int(text[8:10]), tzinfo=UTC)
    except ValueError as exc:
        raise GpmfError(f"GPSU {text!r}: {exc}") from None
    return day.timestamp() + seconds


def payload_gps(payload: bytes) -> list[GpsSamples]:
    """The GPS5/GPS9 streams of one GPMF payload (usually one; none without a GPS).

    Raises
    ------
    GpmfError
        The payload breaks the KLV layout.
    """
    found: list[GpsSamples] = []
    for devc in iter_klv(payload):
        if devc.key != "DEVC" or devc.type:
            continue
        for strm in iter_klv(devc.data):
            if strm.key == "STRM" and not strm.type:
                found.extend(_stream_gps(strm.data))
    return found


def _stream_gps(stream: bytes) -> list[GpsSamples]:
    """GPS samples of one STRM nest: the sticky SCAL/TYPE/GPSF/GPSU/GPSP before the data."""
    scal: list[float] = [1.0]
    type_text: str | None = None
    fix = utc = dop = None
    out: list[GpsSamples] = []
    for item in iter_klv(stream):
        if item.key == "SCAL":
            scal = [float(x) for values in klv_values(item) for x in values]
        elif item.key == "TYPE":
            type_text = klv_values(item)[0][0] if item.repeat else None
        elif item.key == "GPSF":
            fix = int(klv_values(item)[0][0])
        elif item.key == "GPSU":
            utc = gpsu_time(klv_values(item)[0][0])
        elif item.key == "GPSP":
            dop = float(klv_values(item)[0][0]) / 100.0
        elif item.key == "GPS5":
            out.append(_gps5(item, scal, fix, utc, dop))
        elif item.key == "GPS9":
            out.append(_gps9(item, scal, type_text or GPS9_DEFAULT_TYPE))
    return out


def _scaled(values: tuple, scal: list[float], n: int) -> list[float]:
    divisors = scal if len(scal) >= n else [scal[0]] * n
    if any(d == 0 for d in divisors[:n]):
        raise GpmfError("SCAL holds a zero divisor")
    return [float(v) / float(d) for v, d in zip(values[:n], divisors[:n], strict=True)]


def _gps5(item: Klv, scal: list[float], fix: int | None, utc: float | None,
          dop: float | None) -> GpsSamples:
    samples = GpsSamples(kind="GPS5", fix=fix, utc_s=utc)
    for values in klv_values(item):
        if len(values) < 5:
            raise GpmfError(f"GPS5 sample of {len(values)} values, expected 5")
        lat, lon, alt, speed2d, _ = _scaled(values, scal, 5)
        samples.rows.append((lat, lon, alt, speed2d, None, dop))
    return samples


def _gps9(item: Klv, scal: list[float], type_text: str) -> GpsSamples:
    samples = GpsSamples(kind="GPS9")
    for values in klv_values(item, type_text):
        if len(values) < 9:
            raise GpmfError(f"GPS9 sample of {len(values)} values, expected 9")
        lat, lon, alt, speed2d, _, days, secs, dop, fix = _scaled(values, scal, 9)
        if round(fix) < 2:
            samples.n_no_fix += 1
            continue
        utc = GPS9_EPOCH.timestamp() + days * 86400.0 + secs
        samples.rows.append((lat, lon, alt, speed2d, utc, dop))
    return samples
