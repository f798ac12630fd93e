"""KITTI raw tracklets as annotated keyframes: real lidar boxes projected into the video.

Each chosen frame of the drive becomes a :class:`~vid2sim.core.records.Keyframe` whose boxes
are the hulls of the tracklets' 3D boxes in the rectified camera 0 (the video's image_00;
:mod:`vid2sim.evaluate.ranging.tracklets`), with the nearest corner's depth as the
annotation's range. Truncated and largely occluded objects, trams and unknown vehicle classes
are ignore regions; people and cyclists are dropped (the scenario holds vehicles only), as
for the other keyframe formats (:mod:`vid2sim.evaluate.annotations`).

These boxes are projected CUBOIDS, not what an annotator draws around the visible car: a
replay scored against them must project its vehicles as cuboids too (``eval`` does, and says
so in ``metrics.json``'s ``projection``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.base.errors import ImpossibleValueError, InconsistentInputError
from vid2sim.core.records import AnnotatedBox, Keyframe, VehicleCategory
from vid2sim.evaluate.ranging.tracklets import (
    box_corners_velo,
    calibration_beside,
    hull_box_px,
    parse_tracklets,
)

#: What ``metrics.json`` says about the projection of simulated vehicles against tracklets.
CUBOID_PROJECTION = "3D cuboid hull (the keyframes are projected lidar cuboids)"
#: The projection against every other keyframe format.
OUTLINE_PROJECTION = "vehicle outline hull (tyres, body, mirrors; the keyframes are drawn boxes)"
#: The calibration's image size of KITTI raw (S_rect_00), used when the video's is not given.
KITTI_RAW_SIZE_PX = (1242, 375)


@dataclass(frozen=True)
class TrackletKeyframeConfig:
    """Which tracklets count as annotated vehicles.

    ``ignore_occlusion_from``: an object whose KITTI occlusion flag is at least this is an
    ignore region (the flag: 0 fully visible, 1 partly occluded, 2 largely occluded; -1
    unknown, also ignored). 2: a largely hidden car is one no detector is asked to find (the
    KITTI object benchmark's "hard" level), while a partly hidden one keeps its whole cuboid
    in the truth and in the replay alike. ``ignore_truncated``: an object the image border
    truncates (flag >= 1) is an ignore region: its hull is clipped, and whether a detector
    sees the cut rest is a matter of the border, not of the scenario.
    """

    ignore_occlusion_from: int = 2
    ignore_truncated: bool = True


#: Tracklet classes -> (project category, ignore); classes not listed are dropped.
TRACKLET_CLASSES: dict[str, tuple[VehicleCategory | str, bool]] = {
    "Car": (VehicleCategory.CAR, False), "Van": (VehicleCategory.CAR, False),
    "Truck": (VehicleCategory.TRUCK, False), "Tram": (VehicleCategory.TRAM, True),
    "Misc": ("misc", True),
}


def is_tracklet_xml(text: str) -> bool:
    """Whether an XML text is a KITTI tracklet file (boost serialization of tracklets)."""
    head = text[:2000]
    return "<boost_serialization" in head or "<tracklets" in head


def is_tracklet_file(path: str | Path) -> bool:
    """Whether a file is a KITTI tracklet XML (False for anything unreadable: the reader
    reports that)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            return is_tracklet_xml(fh.read(2000))
    except OSError:
        return False


def keyframe_stride(fps: float, rate_hz: float | None) -> int:
    """Every how many frames a keyframe falls at ``rate_hz`` (None: every frame)."""
    if rate_hz is None:
        return 1
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ImpossibleValueError(None, f"keyframe rate {rate_hz} must be a positive number "
                                   "of keyframes a second")
    return max(1, round(fps / rate_hz))


def read_tracklet_keyframes(text: str, path: Path, *, fps: float,
                            calib_dir: Path | None = None, rate_hz: float | None = None,
                            image_size_px: tuple[int, int] | None = None,
                            config: TrackletKeyframeConfig | None = None) -> list[Keyframe]:
    """Keyframes of a tracklet file's text: frames 0, s, 2s, ... (``s`` from ``rate_hz`` at
    ``fps``; every frame without it), the calibration from ``calib_dir`` (default: the XML's
    folder), hulls clipped to ``image_size_px`` (default: KITTI raw's 1242 x 375)."""
    cfg = config or TrackletKeyframeConfig()
    calib = calibration_beside(path, calib_dir)
    size = image_size_px or KITTI_RAW_SIZE_PX
    stride = keyframe_stride(fps, rate_hz)
    by_frame: dict[int, list[AnnotatedBox]] = {}
    for t in parse_tracklets(text, path):
        mapped = TRACKLET_CLASSES.get(t.object_type)
        if mapped is None:
            continue
        category, ignore_class = mapped
        for k, frame in enumerate(t.frames):
            if frame % stride:
                continue
            corners = calib.velo_to_cam(box_corners_velo(t.size_hwl_m, t.pose[k]))
            box = hull_box_px(corners, calib, *size)[0]
            if box is None:
                continue
            occlusion, truncation = int(t.flags[k, 1]), int(t.flags[k, 2])
            ignore = (ignore_class or occlusion < 0 or occlusion >= cfg.ignore_occlusion_from
                      or (cfg.ignore_truncated and truncation != 0))
            by_frame.setdefault(int(frame), []).append(AnnotatedBox(
                box_px=box, category=category, id=str(t.object_id),
                range_m=float(np.min(corners[:, 2])), ignore=ignore))
    if not by_frame:
        raise InconsistentInputError(path, "no tracklet lies in the image on the chosen frames",
                                     "is the calibration for this drive?")
    frames = range(0, max(by_frame) + 1, stride)
    return [Keyframe(frame=f, t_s=f / fps, name=f"{f:06d}", boxes=by_frame.get(f, []))
            for f in frames]
