"""ISO base media file (MP4/MOV) boxes holding telemetry outside any track.

Box layout: ISO/IEC 14496-12 section 4.2 (a 32-bit big-endian size including the 8-byte
header, a four-character type; size 1 = a 64-bit size follows the type, size 0 = the box runs
to the end of the file). Only box headers are read and the file is seeked past each box, so a
recording of gigabytes costs a few reads. (PyAV reads tracks, not free-standing boxes; pymp4
parses each box whole into memory, ``mdat`` included, which a dash-cam file cannot afford.)

BlackVue dash-cams write NMEA 0183 sentences into a ``gps `` box (inside a top-level ``free``
box), each line prefixed with the camera clock in milliseconds since the epoch:
``[1538216648173]$GPRMC,...`` (as described by BlackVue users, e.g. dashcamtalk.com thread
36407, and read by mapillary_tools' blackvue_parser).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from vid2sim.base.errors import FormatError

#: Boxes whose payload is a sequence of boxes, walked for telemetry boxes.
CONTAINER_BOXES = frozenset({"moov", "udta", "free", "meta", "skip"})
#: Boxes that hold NMEA text (BlackVue).
NMEA_BOXES = frozenset({"gps "})
#: Largest telemetry box read into memory [bytes]: an hour of 1 Hz NMEA with its stamps is
#: about 2 MB.
MAX_TELEMETRY_BOX_BYTES = 64 * 1024 * 1024
#: Deepest nesting walked (moov/udta/meta is three).
MAX_DEPTH = 4

_STAMP = re.compile(r"^\s*\[(\d{10,16})\]")


@dataclass(frozen=True, slots=True)
class Box:
    """A box: its type, the offset of its payload and the payload's size [bytes]."""

    type: str
    offset: int
    size: int


def iter_boxes(fh, start: int, end: int, path: Path) -> Iterator[Box]:
    """The boxes between byte ``start`` and ``end`` of an open file, headers only.

    Raises
    ------
    FormatError
        A box that declares more bytes than are left (a truncated recording), or a size
        smaller than its own header.
    """
    pos = start
    while pos + 8 <= end:
        fh.seek(pos)
        head = fh.read(8)
        if len(head) < 8:
            break
        size, kind = int.from_bytes(head[:4], "big"), head[4:8].decode("latin-1")
        header = 8
        if size == 1:
            large = fh.read(8)
            if len(large) < 8:
                raise FormatError(path, f"box '{kind}' at byte {pos} is cut off in its header",
                                  "the recording is truncated")
            size, header = int.from_bytes(large, "big"), 16
        elif size == 0:
            size = end - pos
        if size < header:
            raise FormatError(path, f"box '{kind}' at byte {pos} declares {size} bytes, less "
                              "than its header", "the file is damaged")
        if pos + size > end:
            raise FormatError(path, f"box '{kind}' at byte {pos} declares {size} bytes but "
                              f"only {end - pos} are left", "the recording is truncated")
        yield Box(kind, pos + header, size - header)
        pos += size


def telemetry_boxes(path: Path) -> list[Box]:
    """Every NMEA telemetry box of an MP4/MOV file (see the module docstring)."""
    path = Path(path)
    found: list[Box] = []
    with open(path, "rb") as fh:
        fh.seek(0, 2)
        _walk(fh, 0, fh.tell(), path, found, 0)
    return found


def _walk(fh, start: int, end: int, path: Path, found: list[Box], depth: int) -> None:
    for box in iter_boxes(fh, start, end, path):
        if box.type in NMEA_BOXES:
            found.append(box)
        elif box.type in CONTAINER_BOXES and depth < MAX_DEPTH:
            offset = box.offset + (4 if box.type == "meta" and _is_full_meta(fh, box) else 0)
            try:
                _walk(fh, offset, box.offset + box.size, path, found, depth + 1)
            except FormatError:
                if depth == 0 and box.type == "moov":
                    raise
                continue  # a free/skip box of padding is not made of boxes


def _is_full_meta(fh, box: Box) -> bool:
    """QuickTime's ``meta`` is a plain container, ISO's a full box (4 bytes version/flags)."""
    fh.seek(box.offset)
    return fh.read(4) == b"\x00\x00\x00\x00"


def read_box(path: Path, box: Box) -> bytes:
    """The payload of a box (refused above :data:`MAX_TELEMETRY_BOX_BYTES`)."""
    if box.size > MAX_TELEMETRY_BOX_BYTES:
        raise FormatError(path, f"telemetry box '{box.type}' of {box.size} bytes is larger "
                          f"than {MAX_TELEMETRY_BOX_BYTES // 2**20} MiB", "is the file damaged?")
    with open(path, "rb") as fh:
        fh.seek(box.offset)
        return fh.read(box.size)


def stamped_lines(payload: bytes) -> tuple[list[str], list[float | None]]:
    """The text lines of a BlackVue ``gps `` box and each line's camera stamp [s] (None for
    a line without one): ``[1538216648173]$GPRMC,...`` -> 1538216648.173."""
    text = payload.replace(b"\x00", b"\n").decode("ascii", errors="replace")
    lines, stamps = [], []
    for line in text.splitlines():
        # a stamp may also close the previous line ("...*7D[1538216649174]")
        for part in re.split(r"(?=\[\d{10,16}\])", line):
            if not part.strip():
                continue
            m = _STAMP.match(part)
            lines.append(part[m.end():] if m else part)
            stamps.append(int(m.group(1)) / 1000.0 if m else None)
    return lines, stamps
