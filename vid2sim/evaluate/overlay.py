"""The camera half of a replay frame: what the build saw, and the scenario seen back through
the same camera.

On the video frame:

- the detected boxes of the frame (``tracks.csv``), labelled ``#id lane range range-rate`` and
  coloured by their lane relative to the ego lane (as the report's sampled frames: orange the
  ego lane, blue left, green right, grey other or unknown; the lead thicker);
- the scenario's vehicles at the frame's time, projected back through the scenario camera
  (:func:`vid2sim.evaluate.projection.project_hull`: the hull of the outline a detector's box
  hugs), drawn as that hull and coloured by the IoU of its box with the detection of the
  same track in this frame: green at or above :attr:`OverlayConfig.iou_good`, yellow at or
  above :attr:`OverlayConfig.iou_fair`, red below, magenta where the track has no box in
  this frame (the scenario holds a vehicle the video did not show then). Vehicles hidden
  behind nearer ones are dropped as the replay evaluation drops them
  (:func:`vid2sim.evaluate.replay.boxes_at`);
- the ego lane's boundaries: the scenario's (the edges of the lane of the road's
  cross-section the ego is in, cyan), and the ones the lane-marking track measured (yellow)
  where the caller has them;
- annotated keyframe boxes (white; ignore regions grey) on keyframes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from vid2sim.core.boxes import iou_matrix
from vid2sim.core.camera import Camera
from vid2sim.core.outline import CAR_SHAPE, CLASS_SHAPES, OutlineShape
from vid2sim.core.records import Keyframe, ProjectedBox, RangedBox
from vid2sim.core.scenario import Scenario
from vid2sim.evaluate.birdseye import outlined_text
from vid2sim.evaluate.projection import project_hull
from vid2sim.evaluate.replay import boxes_at
from vid2sim.evaluate.replayconfig import OverlayConfig

_LANE_BGR = {0: (0, 140, 255), 1: (255, 120, 40), -1: (60, 180, 60)}
_UNKNOWN_BGR = (150, 150, 150)
_GOOD_BGR, _FAIR_BGR, _POOR_BGR = (60, 220, 60), (0, 220, 255), (50, 50, 240)
_UNSEEN_BGR = (230, 60, 230)
_SCENARIO_LANE_BGR = (255, 255, 0)
_MEASURED_LANE_BGR = (0, 230, 255)
_KEYFRAME_BGR, _IGNORE_BGR = (255, 255, 255), (150, 150, 150)


@dataclass(frozen=True, slots=True)
class SimVehicle:
    """A scenario vehicle in the camera: its box, the hull drawn (K, 2) [px] and the IoU of
    its box with the detection of the same track in the frame (None: no such detection)."""

    box: ProjectedBox
    hull_px: np.ndarray
    iou: float | None


def track_of(actor_id: str) -> int | None:
    """The track id an actor was assembled from: ``"12"`` and ``"12-2"`` (a track split at
    a gap) -> 12; None for an id that names no track."""
    head = actor_id.split("-", 1)[0]
    return int(head) if head.isdigit() else None


def scenario_in_camera(scenario: Scenario, camera: Camera, ego: tuple[float, float, float],
                       actors: dict[str, tuple[float, float, float]],
                       detected: Sequence[RangedBox],
                       outlines: dict[str, OutlineShape] | None = CLASS_SHAPES
                       ) -> list[SimVehicle]:
    """The scenario's vehicles (ENU poses ``actors`` seen from the ego pose ``ego``) in the
    camera, each with its hull and the IoU with its track's detected box (``detected``: the
    boxes of the same frame)."""
    boxes = boxes_at(scenario, camera, ego, actors, outlines)
    if not boxes:
        return []
    by_track = {b.track_id: b for b in detected}
    by_id = {a.id: a for a in scenario.actors}
    ex, ey, eh = ego
    c, s = np.cos(eh), np.sin(eh)
    out = []
    for box in boxes:
        a = by_id[box.actor_id]
        ax, ay, ah = actors[a.id]
        dx, dy = ax - ex, ay - ey
        centre = np.array([c * dx + s * dy, -s * dx + c * dy, 0.0])
        hull = project_hull(camera, centre, a.length_m, a.width_m, a.height_m, ah - eh,
                            outline=outlines and outlines.get(a.category, CAR_SHAPE))
        if hull is None:
            continue
        seen = by_track.get(track_of(a.id))
        iou = None
        if seen is not None:
            iou = float(iou_matrix([box.box_px], [[seen.x1, seen.y1, seen.x2, seen.y2]])[0, 0])
        out.append(SimVehicle(box, hull, iou))
    return out


def iou_colour(iou: float | None, config: OverlayConfig) -> tuple[int, int, int]:
    """The hull's colour for an IoU (see the module docstring)."""
    if iou is None:
        return _UNSEEN_BGR
    if iou >= config.iou_good:
        return _GOOD_BGR
    return _FAIR_BGR if iou >= config.iou_fair else _POOR_BGR


def lane_edges_px(camera: Camera, ego: tuple[float, float, float],
                  edges_enu: Sequence[np.ndarray], config: OverlayConfig) -> list[np.ndarray]:
    """ENU polylines (the ego lane's edges) as pixel polylines, the part between
    :attr:`OverlayConfig.lane_near_m` and :attr:`OverlayConfig.lane_far_m` ahead."""
    ex, ey, eh = ego
    c, s = np.cos(eh), np.sin(eh)
    out = []
    for line in edges_enu:
        dx, dy = line[:, 0] - ex, line[:, 1] - ey
        fwd, left = c * dx + s * dy, -s * dx + c * dy
        keep = (fwd >= config.lane_near_m) & (fwd <= config.lane_far_m)
        if keep.sum() < 2:
            continue
        pts = np.column_stack((fwd[keep], left[keep], np.zeros(int(keep.sum()))))
        uv, ok = camera.project(pts)
        if ok.sum() >= 2:
            out.append(uv[ok])
    return out


def draw_camera(image_bgr: np.ndarray, detected: Sequence[RangedBox],
                sims: Sequence[SimVehicle], scenario_lanes: Sequence[np.ndarray] = (),
                measured_lanes: Sequence[np.ndarray] = (), keyframe: Keyframe | None = None,
                config: OverlayConfig | None = None) -> np.ndarray:
    """Draw the camera half (module docstring) onto ``image_bgr`` (in place) and return it."""
    cfg = config or OverlayConfig()
    img = image_bgr
    scale = max(img.shape[1] / 1280.0, 0.5)
    thick = max(1, round(2 * scale))
    for lines, colour in ((scenario_lanes, _SCENARIO_LANE_BGR),
                          (measured_lanes, _MEASURED_LANE_BGR)):
        for line in lines:
            cv2.polylines(img, [np.round(line).astype(np.int32)], False, colour, thick,
                          cv2.LINE_AA)
    labels = _Labels(img, 0.42 * scale)
    for sim in sims:
        colour = iou_colour(sim.iou, cfg)
        cv2.polylines(img, [np.round(sim.hull_px).astype(np.int32)], True, colour,
                      1 if sim.box.hard else thick, cv2.LINE_AA)
        x1, _, _, y2 = sim.box.box_px
        text = sim.box.actor_id + ("" if sim.iou is None else f" {sim.iou:.2f}")
        labels.place(text, round(x1), round(y2) + labels.height + 4, colour, down=True)
    if keyframe is not None:
        for a in keyframe.boxes:
            p1 = (round(a.box_px[0]), round(a.box_px[1]))
            p2 = (round(a.box_px[2]), round(a.box_px[3]))
            cv2.rectangle(img, p1, p2, _IGNORE_BGR if a.ignore else _KEYFRAME_BGR, 1,
                          cv2.LINE_AA)
    for b in sorted(detected, key=lambda b: -b.y2):  # nearest (lowest) first
        _draw_detection(img, b, scale, labels)
    draw_legend(img, cfg, bool(measured_lanes))
    return img


class _Labels:
    """Places labels where they overlap no earlier one: moved a line up (or down) at a time,
    up to three lines, then drawn where the last try put them."""

    def __init__(self, img: np.ndarray, font_scale: float):
        self.img, self.scale = img, font_scale
        self.height = cv2.getTextSize("Ag", cv2.FONT_HERSHEY_SIMPLEX, font_scale, 1)[0][1] + 3
        self.taken: list[tuple[int, int, int, int]] = []

    def place(self, text: str, u: int, v: int, colour: tuple[int, int, int],
              down: bool = False) -> None:
        h_img, w_img = self.img.shape[:2]
        w = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, self.scale, 1)[0][0]
        u = int(min(max(u, 2), w_img - w - 2))
        step = self.height if down else -self.height
        for _ in range(4):
            v = int(min(max(v, self.height), h_img - 3))
            rect = (u, v - self.height, u + w, v)
            if not any(rect[0] < r[2] and r[0] < rect[2] and rect[1] < r[3] and r[1] < rect[3]
                       for r in self.taken):
                break
            v += step
        self.taken.append(rect)
        outlined_text(self.img, text, (u, v), self.scale, colour)


def _draw_detection(img: np.ndarray, b: RangedBox, scale: float, labels: _Labels) -> None:
    lane = b.lane
    colour = _LANE_BGR.get(lane, _UNKNOWN_BGR) if lane is not None else _UNKNOWN_BGR
    p1, p2 = (round(b.x1), round(b.y1)), (round(b.x2), round(b.y2))
    cv2.rectangle(img, p1, p2, colour, (3 if b.is_lead else 1) * max(1, round(scale)),
                  cv2.LINE_8)
    lane_txt = "?" if lane is None else f"{lane:+d}" if lane else "0"
    parts = [f"#{b.track_id}", f"L{lane_txt}"]
    if np.isfinite(b.range_m):
        parts.append(f"{b.range_m:.0f}m")
    if np.isfinite(b.range_rate_mps):
        parts.append(f"{b.range_rate_mps:+.1f}m/s")
    labels.place(" ".join(parts), p1[0], p1[1] - 4, colour)


def draw_legend(img: np.ndarray, config: OverlayConfig, measured: bool) -> None:
    """One line at the top left saying what the colours mean, on a dark band."""
    scale = max(img.shape[1] / 1280.0 * 0.42, 0.3)
    items = [("detected, by lane: 0", _LANE_BGR[0]), ("+1", _LANE_BGR[1]), ("-1", _LANE_BGR[-1]),
             ("other", _UNKNOWN_BGR), ("| scenario, IoU:", (235, 235, 235)),
             (f">={config.iou_good:g}", _GOOD_BGR), (f">={config.iou_fair:g}", _FAIR_BGR),
             (f"<{config.iou_fair:g}", _POOR_BGR), ("undetected", _UNSEEN_BGR),
             ("| lane: scenario", _SCENARIO_LANE_BGR)]
    if measured:
        items.append(("measured", _MEASURED_LANE_BGR))
    h = cv2.getTextSize("Ag", cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][1]
    widths = [cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0] for t, _ in items]
    cv2.rectangle(img, (0, 0), (sum(widths) + 8 * len(items) + 8, h + 10), (25, 25, 25),
                  cv2.FILLED)
    u = 6
    for (text, colour), w in zip(items, widths, strict=True):
        cv2.putText(img, text, (u, h + 4), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, 1,
                    cv2.LINE_AA)
        u += w + 8
