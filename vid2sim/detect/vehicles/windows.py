"""Where the detector looks in a frame: the full frame, two half-frame tiles, a centre window,
and crops about lead candidates for refinement (see :mod:`vid2sim.detect.vehicles.detector`).

Windows are (x1, y1, x2, y2) in frame pixels; all functions are pure geometry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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


# --------------------------------------------------------------------------- looks

Window = tuple[int, int, int, int]


@dataclass(frozen=True, slots=True)
class Look:
    """Where one detector run looks: its windows (x1, y1, x2, y2) [frame px], the first the
    full frame, and which of them is the centre window (only its confident boxes are kept,
    see :data:`vid2sim.detect.vehicles.detector.CENTRE_MIN_SCORE`).

    :param windows: the windows, the full frame first
    :param centre: the centre window (or its cut to a band), None without one
    :param sweep: every window of the detector's full run (:func:`full_look`); False for a
        look cut to a band (:func:`band_look`) or to crops (:func:`local_look`), whose misses
        the tracker must not count where it did not look (:func:`seen_by`)
    :param caps: per window, the largest net pixels per frame pixel it is seen at (a crop
        seen at the scale of the window it was cut from), None for none
    :param refine: whether the lead candidates are refined on crops after this look
    """

    windows: tuple[Window, ...]
    centre: Window | None = None
    sweep: bool = True
    caps: tuple[float | None, ...] | None = None
    refine: bool = True

    def scale(self, index: int, input_size_px: tuple[int, int]) -> float:
        """Net pixels per frame pixel of window ``index``."""
        natural = net_scale(self.windows[index], input_size_px)
        cap = None if self.caps is None else self.caps[index]
        return natural if cap is None else min(natural, cap)


def full_look(width_px: int, height_px: int, tiles: bool = True) -> Look:
    """The detector's full run: the frame, and with ``tiles`` (the small-object mode) the two
    half-frame tiles and the centre window of a frame wider than 4:3 (:func:`tile_windows`)."""
    windows = tile_windows(width_px, height_px) if tiles else [(0, 0, width_px, height_px)]
    centre = centre_window(width_px, height_px) if len(windows) > 1 else None
    return Look(tuple(windows), centre, sweep=True)


MIN_BAND_ROWS_PX = 32
"""A window cut to a band lower than this [frame px] is left out (nothing a net finds)."""


def band_look(full: Look, rows_px: tuple[float, float]) -> Look:
    """``full`` with every window but the full frame cut to the image rows ``rows_px``
    (y1, y2): where far (small) vehicles are, about the horizon. Windows keep their width,
    so their scale (set by the width in a wide frame) is the full run's."""
    y1, y2 = math.floor(rows_px[0]), math.ceil(rows_px[1])
    out = [full.windows[0]]
    centre = None
    for x1, wy1, x2, wy2 in full.windows[1:]:
        cut = (x1, max(wy1, y1), x2, min(wy2, y2))
        if cut[3] - cut[1] < MIN_BAND_ROWS_PX:
            continue
        out.append(cut)
        if (x1, wy1, x2, wy2) == full.centre:
            centre = cut
    return Look(tuple(out), centre, sweep=False)


def net_scale(window: Window, input_size_px: tuple[int, int]) -> float:
    """Net input pixels per frame pixel of a window letterboxed into the net's input
    (width, height): the smaller of the two ratios."""
    x1, y1, x2, y2 = window
    return min(input_size_px[0] / max(x2 - x1, 1), input_size_px[1] / max(y2 - y1, 1))


def best_scales(boxes_px: np.ndarray, look: Look, input_size_px: tuple[int, int]) -> np.ndarray:
    """Per box (frame px, Nx4, clipped to the frame by the caller): the largest scale at which
    a window of ``look`` holds it whole (0 where none does)."""
    boxes_px = np.asarray(boxes_px, dtype=float).reshape(-1, 4)
    best = np.zeros(len(boxes_px))
    for i, (x1, y1, x2, y2) in enumerate(look.windows):
        inside = ((boxes_px[:, 0] >= x1) & (boxes_px[:, 1] >= y1)
                  & (boxes_px[:, 2] <= x2) & (boxes_px[:, 3] <= y2))
        best = np.where(inside, np.maximum(best, look.scale(i, input_size_px)), best)
    return best


LOCAL_CROP_SIDES = 3.0
"""Side of a crop about a box a keyframe looks at alone (:func:`local_look`), in the box's
larger sides: a box width of context on each side, so the car moved by a few frames of
prediction error is still whole inside (a box touching a crop edge is dropped)."""

LOCAL_CROP_MARGIN_PX = 16
"""Frame pixels added on each side of such a crop (small, far boxes)."""


def local_look(boxes_px: np.ndarray, full: Look, input_size_px: tuple[int, int],
               image_size_px: tuple[int, int], refine: bool = True) -> Look:
    """Crops about ``boxes_px`` (frame px, Nx4), each seen at the scale the full run ``full``
    would see its box at (the largest of the windows holding it whole): a second look at a
    few tracks, at the cost of their crops' pixels; with ``refine`` a lead candidate among
    what they find is refined as after a full run."""
    w, h = image_size_px
    boxes = np.clip(np.asarray(boxes_px, dtype=float).reshape(-1, 4), 0, [w, h, w, h])
    scales = best_scales(boxes, full, input_size_px)
    windows, caps = [], []
    for box, scale in zip(boxes, scales, strict=True):
        side = LOCAL_CROP_SIDES * max(box[2] - box[0], box[3] - box[1]) + 2 * LOCAL_CROP_MARGIN_PX
        cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
        window = (int(max(0, round(cx - side / 2))), int(max(0, round(cy - side / 2))),
                  int(min(w, round(cx + side / 2))), int(min(h, round(cy + side / 2))))
        if window[2] - window[0] < 2 or window[3] - window[1] < 2 or window in windows:
            continue
        windows.append(window)
        caps.append(float(scale) if scale > 0 else None)
    return Look(tuple(windows), None, sweep=False, caps=tuple(caps), refine=refine)


def seen_by(boxes_px: np.ndarray, look: Look, full: Look, input_size_px: tuple[int, int],
            min_net_px: float, image_size_px: tuple[int, int]) -> np.ndarray:
    """Which boxes (frame px, Nx4) ``look`` looked at as well as the full run ``full`` would
    have, or at least at ``min_net_px`` of box height in the net's input: a vehicle there
    would have been found, so a track there that no detection took is a miss. Elsewhere the
    detector did not look (the tracker carries the track by flow instead)."""
    w, h = image_size_px
    boxes = np.clip(np.asarray(boxes_px, dtype=float).reshape(-1, 4), 0, [w, h, w, h])
    if look.sweep:
        return np.ones(len(boxes), dtype=bool)
    height = np.maximum(boxes[:, 3] - boxes[:, 1], 1.0)
    enough = np.minimum(best_scales(boxes, full, input_size_px), min_net_px / height)
    return best_scales(boxes, look, input_size_px) >= enough * (1.0 - 1e-9)


PRECISE_NET_PX = 48.0
"""A box at least this tall in the net's input is measured by the full frame alone in a
keyframe that looks at the tracks (:func:`tracks_look`): its edges' noise, a pixel or two
of the net's, is then 2-4 % of its height, as a sweep's windows give a 24 px box."""


def tracks_look(boxes_px: np.ndarray, full: Look, input_size_px: tuple[int, int],
                image_size_px: tuple[int, int], precise_net_px: float = PRECISE_NET_PX
                ) -> Look:
    """The full frame (near cars anywhere, and those entering at the image's sides) and a
    crop about every box (frame px, Nx4) the full frame sees smaller than ``precise_net_px``,
    at the scale a sweep sees it at (:func:`local_look`), overlapping crops of one scale
    merged: every tracked car measured as a sweep would measure it, for the pixels of the
    crops; new far cars wait for the next sweep."""
    w, h = image_size_px
    boxes = np.clip(np.asarray(boxes_px, dtype=float).reshape(-1, 4), 0, [w, h, w, h])
    full_scale = full.scale(0, input_size_px)
    small = boxes[(boxes[:, 3] - boxes[:, 1]) * full_scale < precise_net_px]
    crops = local_look(small, full, input_size_px, image_size_px)
    keep = [i for i, cap in enumerate(crops.caps) if cap is not None and cap > full_scale]
    windows, caps = _merged([crops.windows[i] for i in keep], [crops.caps[i] for i in keep])
    return Look((full.windows[0], *windows), None, sweep=False, caps=(None, *caps))


def _merged(windows: list[Window], caps: list[float]) -> tuple[list[Window], list[float]]:
    """Windows of one scale that overlap replaced by their union while it is no larger than
    the two apart (fewer net runs for the same pixels)."""
    windows, caps = list(windows), list(caps)
    merged = True
    while merged:
        merged = False
        for i in range(len(windows)):
            for j in range(i + 1, len(windows)):
                a, b = windows[i], windows[j]
                if caps[i] != caps[j]:
                    continue
                union = (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))
                if _area(union) <= _area(a) + _area(b):
                    windows[i] = union
                    del windows[j], caps[j]
                    merged = True
                    break
            if merged:
                break
    return windows, caps


def _area(window: Window) -> int:
    return max(0, window[2] - window[0]) * max(0, window[3] - window[1])
