"""Where the detector looks in a frame: the full frame, two half-frame tiles, a centre window,
and crops about lead candidates for refinement (see :mod:`vid2sim.detect.vehicles.detector`).

Windows are (x1, y1, x2, y2) in frame pixels; all functions are pure geometry.
"""

from __future__ import annotations

import numpy as np

WIDE_ASPECT = 1.34
"""Frames wider than this (width over height, a little above 4:3) get the two half-frame
tiles: a 4:3 or squarer frame already fills most of the net's square input."""

TILE_OVERLAP = 0.1
"""Overlap of the two half-frame tiles, as a fraction of the half width: a car up to this
many half-widths wide in the middle of the frame is whole in one tile."""

REFINE_MAX_BOXES = 1
"""Vehicles refined on a crop per detector run by default with the small-object mode (nearest
lead candidates first); each costs one more run of the net. Composite clips (6 seeds, the
detector on every frame): 1 box lead range 2.9 %, rate RMSE 0.594 m/s; 2 boxes 2.9 %, 0.589
(with keyframes every 0.3 s: 0.629 and 0.635 m/s): the second box bought nothing there."""

REFINE_CROP_SCALE = 5.0
"""Side of a refinement crop over the larger side of the box. On the composite clips: at 2.5
a quarter of the car's boxes were lost (too little context); at 3 the lead range-rate RMSE
was 0.96 m/s, at 4 0.83 m/s but the range bias grew from +5.0 % to +6.5 %, at 5 0.85 m/s with
the range bias +5.3 % (1.00 m/s and +5.0 % unrefined)."""

REFINE_MIN_SIDE_PX = 96.0
"""Smallest refinement crop side [frame px], so a small far car (416 / 96 = 4.3x) is not
blown up beyond the scale the net was trained at. Not tuned: the composite clips' car is 24
px wide or more, so 64 and 96 gave the same figures there."""

REFINE_MIN_IOU = 0.5
"""IoU with the box being refined from which a crop box replaces it: at 0.3 boxes of other
shapes took its place, and the composite clips' lead range error grew from 6.5 % to 8.0 %
(crop 4x)."""

REFINE_MAX_OFFSET_WIDTHS = 1.5
"""Refinement candidates have their box centre at most this many box widths from the image
centre line: about 2.5 m for a car, so the lead in the ego lane and cars cutting in, not
the parked cars at the kerb, which stand lower (nearer) in the image."""

REFINE_MIN_HEIGHT_PX = 10.0
"""Boxes lower than this [px] are not refined (too few pixels to gain from)."""

REFINE_MAX_WIDTH_FRACTION = 0.25
"""Boxes wider than this fraction of the image width are not refined: their crop would be
about the frame itself, and their edge noise is already small against their width."""


def tile_windows(width_px: int, height_px: int, overlap: float = TILE_OVERLAP,
                 centre: bool = True
                 ) -> list[tuple[int, int, int, int]]:
    """Windows (x1, y1, x2, y2) [px] the detector runs on: the full frame, plus for a frame
    wider than 4:3 a left and a right tile: the two halves, each widened by ``overlap``
    (fraction of the half width) into the other, and at least as wide as the frame is high,
    so a car up to ``overlap`` half-widths wide in the middle is whole in one tile."""
    windows = [(0, 0, width_px, height_px)]
    if width_px <= WIDE_ASPECT * height_px:
        return windows
    tile_w = int(min(width_px, max(height_px, round(width_px / 2 * (1.0 + overlap)))))
    windows.append((0, 0, tile_w, height_px))
    windows.append((width_px - tile_w, 0, width_px, height_px))
    if centre:
        windows.append(centre_window(width_px, height_px))
    return windows


def centre_window(width_px: int, height_px: int) -> tuple[int, int, int, int]:
    """A square of a third of the width (at most the height) about the image centre, where a
    forward camera sees the road ahead: a lead 30-45 m away is seen at about the net's own
    scale."""
    side = int(min(height_px, round(width_px / 3)))
    cx1, cy1 = (width_px - side) // 2, (height_px - side) // 2
    return cx1, cy1, cx1 + side, cy1 + side


def refine_crop(box_px, width_px: int, height_px: int, scale: float = REFINE_CROP_SCALE,
                min_side_px: float = REFINE_MIN_SIDE_PX) -> tuple[int, int, int, int]:
    """Crop (x1, y1, x2, y2) [px] to refine ``box_px`` on: a square of side ``scale`` times
    the box's larger side (at least ``min_side_px``) centred on the box, clipped to the
    image (so a crop at the image border is no longer square)."""
    bx1, by1, bx2, by2 = (float(v) for v in box_px)
    side = max(scale * max(bx2 - bx1, by2 - by1), min_side_px)
    cx, cy = (bx1 + bx2) / 2, (by1 + by2) / 2
    x1 = int(max(0, round(cx - side / 2)))
    y1 = int(max(0, round(cy - side / 2)))
    x2 = int(min(width_px, round(cx + side / 2)))
    y2 = int(min(height_px, round(cy + side / 2)))
    return x1, y1, x2, y2


def refine_candidates(boxes_px: np.ndarray, width_px: int, max_boxes: int,
                      max_offset_widths: float = REFINE_MAX_OFFSET_WIDTHS,
                      min_height_px: float = REFINE_MIN_HEIGHT_PX,
                      max_width_fraction: float = REFINE_MAX_WIDTH_FRACTION) -> np.ndarray:
    """Indices of the boxes (Nx4, frame px) worth refining, nearest first.

    Lead candidates: box centre at most ``max_offset_widths`` box widths from the image's
    vertical centre line (a lateral offset in car widths, whatever the range), height at
    least ``min_height_px``, width at most ``max_width_fraction`` of the image width.
    Nearest first is lowest bottom edge first (on a flat road a nearer car stands lower in
    the image); at most ``max_boxes``.
    """
    boxes_px = np.asarray(boxes_px, dtype=float).reshape(-1, 4)
    if max_boxes <= 0 or len(boxes_px) == 0:
        return np.zeros(0, dtype=np.int64)
    centre_x = (boxes_px[:, 0] + boxes_px[:, 2]) / 2
    w = boxes_px[:, 2] - boxes_px[:, 0]
    h = boxes_px[:, 3] - boxes_px[:, 1]
    ok = ((np.abs(centre_x - width_px / 2) <= max_offset_widths * w)
          & (h >= min_height_px) & (w <= max_width_fraction * width_px))
    idx = np.flatnonzero(ok)
    idx = idx[np.argsort(-boxes_px[idx, 3], kind="stable")]
    return idx[:max_boxes].astype(np.int64)
