"""Boxes made by other tools or people: MOT-challenge CSV, Scalabel/BDD100K JSON, KITTI labels,
and this project's own detections.csv.

Frame convention: every reader returns 0-based frame indices, the project's convention
(frame 0 is the video's first frame). MOT-challenge files count from 1, so MOT frame f is
our frame f - 1. Scalabel frames use ``frameIndex`` (0-based, as BDD100K writes it), else
``index``, else their order in the file sorted by ``name``.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.base.errors import FormatError, ImpossibleValueError, MissingInputError
from vid2sim.base.fileio import parse_json, read_input_text
from vid2sim.core.boxes import iou_matrix, match
from vid2sim.core.records import Detection, VehicleCategory

# Category names other tools use -> ours. Anything absent (pedestrian, bicycle...) is not a
# vehicle we track and is dropped. Trains and trams (COCO "train", KITTI "Tram", BDD100K
# "train") are rail vehicles: our "tram".
_C = VehicleCategory
CATEGORY_ALIASES: dict[str, VehicleCategory] = {
    "car": _C.CAR, "van": _C.CAR, "suv": _C.CAR, "vehicle": _C.CAR, "pickup": _C.TRUCK,
    "truck": _C.TRUCK, "lorry": _C.TRUCK, "trailer": _C.TRUCK, "bus": _C.BUS,
    "motorcycle": _C.MOTORCYCLE, "motorbike": _C.MOTORCYCLE, "motor": _C.MOTORCYCLE,
    "tram": _C.TRAM, "train": _C.TRAM, "streetcar": _C.TRAM, "light_rail": _C.TRAM,
}
# MOT16/17 ground-truth class ids (Milan et al. 2016, table of classes): 3 car,
# 5 motorbike; the other classes are not vehicles we track.
MOT_CLASS_IDS: dict[int, VehicleCategory] = {3: _C.CAR, 5: _C.MOTORCYCLE}


def _category(name: str) -> VehicleCategory | None:
    return CATEGORY_ALIASES.get(name.strip().lower())


#: Largest |pixel coordinate| of an imported box [px]: boxes reach a little past the image
#: edge; 100,000 px is beyond any frame (16K video is 15,360 px wide).
MAX_BOX_COORD_PX = 100_000.0
#: Largest imported frame number: a month of video at 30 frames/s.
MAX_FRAME_INDEX = 100_000_000


def read_detections(path: Path) -> dict[int, list[Detection]]:
    """Read boxes from a MOT-challenge CSV/TXT or a Scalabel/BDD100K JSON file.

    Parameters
    ----------
    path : Path
        ``.json`` is read as Scalabel; a CSV whose header is this project's
        ``frame,t_s,track_id,category,score,x1,y1,x2,y2`` as ``detections.csv``; anything
        else as MOT-challenge CSV.

    Returns
    -------
    dict
        0-based frame index -> detections in that frame (vehicles only).

    Raises
    ------
    InputError
        If the file is missing, binary or not in either format, or a vehicle row holds a box
        that is not finite, has no area (x2 <= x1 or y2 <= y1, w or h <= 0) or lies beyond
        any frame, a score that is not a number in [0, 1] (MOT's -1: unknown), or a frame
        number that is not a video's. Such a row is an error, not skipped: a file with one is
        broken, and the boxes it would leave out are cars missing from the scenario.
    """
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(path, "no such detections file")
    text = read_input_text(path)
    try:
        if path.suffix.lower() == ".json":
            return _read_scalabel_text(text, path)
        header = text.split("\n", 1)[0].strip().replace(" ", "")
        if header.startswith("frame,t_s,track_id,category,score,x1,y1,x2,y2"):
            return _read_vid2sim_text(text, path)
        return _read_mot_text(text, path)
    except csv.Error as exc:
        raise FormatError(path, f"not a readable CSV: {exc}") from None


def _checked(path: Path, where: str, frame: int, box: tuple[float, float, float, float],
             score: float) -> None:
    """Raise :class:`InputError` for an imported box or score no detector could give."""
    if not 0 <= frame <= MAX_FRAME_INDEX:
        raise ImpossibleValueError(path, f"{where}: frame {frame} is not a video frame number")
    if not all(math.isfinite(v) for v in (*box, score)):
        raise ImpossibleValueError(
            path, f"{where}: box {box} or score {score} is not a finite number",
            "every box needs finite pixel coordinates")
    x1, y1, x2, y2 = box
    if x2 <= x1 or y2 <= y1:
        raise ImpossibleValueError(
            path, f"{where}: box {box} has no area (width {x2 - x1:g}, height "
            f"{y2 - y1:g} px)", "remove the row, or fix its size")
    if max(abs(v) for v in box) > MAX_BOX_COORD_PX:
        raise ImpossibleValueError(path, f"{where}: box {box} lies beyond any frame")
    if not 0.0 <= score <= 1.0:
        raise ImpossibleValueError(path, f"{where}: score {score:g} outside [0, 1]")


def _read_vid2sim_text(text: str, path: Path) -> dict[int, list[Detection]]:
    out: dict[int, list[Detection]] = {}
    for n, row in enumerate(csv.DictReader(io.StringIO(text)), start=2):
        try:
            frame = int(row["frame"])
            box = tuple(float(row[k]) for k in ("x1", "y1", "x2", "y2"))
            score = float(row["score"])
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise FormatError(path, f"line {n}: {exc}", "columns: frame,t_s,track_id,"
                              "category,score,x1,y1,x2,y2") from None
        category = _category(row.get("category") or "")
        if category is None:
            continue
        _checked(path, f"line {n}", frame, box, score)
        out.setdefault(frame, []).append(Detection(box_px=box, score=score, category=category))
    return out


def _read_mot_text(text: str, path: Path) -> dict[int, list[Detection]]:
    """Read a MOT-challenge file: ``frame,id,x,y,w,h,score[,class|x[,visibility|y[,z]]]``.

    - ``frame`` is 1-based (MOT convention) and becomes ``frame - 1``;
    - ``x, y`` is the top-left corner, ``w, h`` the size [px];
    - ``score`` -1 (unknown) becomes 1.0;
    - the 8th column, when present and not -1, is the class: a category name (car, truck,
      bus, motorcycle, van...) or, in 8/9-column ground-truth files, a MOT16/17 class id
      (3 car, 5 motorbike; others dropped); there column 7 is a "consider" flag, not a
      score: rows flagged 0 are dropped and the others get score 1.0;
    - 10-column detection files (``...,score,x,y,z`` with world coordinates -1) and files
      without a class give every box the category car; non-vehicle names are dropped.
    """
    out: dict[int, list[Detection]] = {}
    delimiter = "," if "," in text[:4096] else None
    lines = (csv.reader(io.StringIO(text), delimiter=delimiter) if delimiter
             else (line.split() for line in text.splitlines()))
    for n, row in enumerate(lines, start=1):
        row = [c.strip() for c in row]
        if not row or not any(row) or row[0].startswith("#"):
            continue
        if n == 1 and not _is_number(row[0]):
            continue  # a header line
        if len(row) < 6:
            raise FormatError(path, f"line {n}: expected at least 6 columns "
                              f"(frame,id,x,y,w,h[,score,...]), got {len(row)}",
                              "is this a MOT-challenge file?")
        klass = row[7] if len(row) > 7 else ""
        try:
            frame = int(float(row[0]))
            x, y, w, h = (float(v) for v in row[2:6])
            score = float(row[6]) if len(row) > 6 and row[6] else 1.0
            class_id = (int(float(klass)) if klass and _is_number(klass) and klass != "-1"
                        else None)
        except (ValueError, OverflowError) as exc:
            raise FormatError(path, f"line {n}: {exc}", "MOT columns must be numbers") from None
        if frame < 1:
            raise ImpossibleValueError(path, f"line {n}: frame {frame} < 1",
                                       "MOT-challenge frames count from 1")
        category: VehicleCategory | None = _C.CAR
        if klass and not _is_number(klass):
            category = _category(klass)
        elif class_id is not None and len(row) <= 9:
            # Ground-truth layout: column 7 is a "consider" flag (0 = ignore), not a score.
            if len(row) == 9 and score == 0.0:
                continue
            category = MOT_CLASS_IDS.get(class_id)
            score = 1.0
        # (10-column detection files carry world x, y, z = -1 after the score: ignored.)
        if category is None:
            continue
        if score < 0:
            score = 1.0  # -1 = confidence unknown
        box = (x, y, x + w, y + h)
        _checked(path, f"line {n}", frame - 1, box, min(score, 1.0))
        out.setdefault(frame - 1, []).append(
            Detection(box_px=box, score=min(score, 1.0), category=category))
    return out


def _read_scalabel_text(text: str, path: Path) -> dict[int, list[Detection]]:
    """Read a Scalabel / BDD100K JSON: a list of frames, or ``{"frames": [...]}``.

    Each frame has ``name`` and ``frameIndex`` (or ``index``), and ``labels``: objects with
    ``category`` and ``box2d`` {x1, y1, x2, y2} [px], optionally ``score``. Non-vehicle
    categories and labels without a ``box2d`` are dropped.
    """
    data = parse_json(text, path)
    frames = data.get("frames") if isinstance(data, dict) else data
    if not isinstance(frames, list):
        raise FormatError(path, "expected a list of frames or an object with 'frames'",
                          "is this a Scalabel/BDD100K label file?")
    has_index = all(isinstance(f, dict) and ("frameIndex" in f or "index" in f) for f in frames)
    if not has_index:
        frames = sorted(frames, key=lambda f: str(f.get("name", "")) if isinstance(f, dict)
                        else "")
    out: dict[int, list[Detection]] = {}
    for order, item in enumerate(frames):
        if not isinstance(item, dict):
            raise FormatError(path, f"frame {order} is not an object")
        try:
            index = (_whole(item.get("frameIndex", item.get("index", order))) if has_index
                     else order)
        except (TypeError, ValueError, OverflowError):
            raise FormatError(path, f"frame {order}: frameIndex/index is not a whole number"
                              ) from None
        labels = item.get("labels") or []
        if not isinstance(labels, list):
            raise FormatError(path, f"frame {index}: labels must be a list")
        dets = out.setdefault(index, [])
        for label in labels:
            box = label.get("box2d") if isinstance(label, dict) else None
            category = _category(str(label.get("category", ""))) if box else None
            if box is None or category is None:
                continue
            try:
                x1, y1, x2, y2 = (_real(box[k]) for k in ("x1", "y1", "x2", "y2"))
                score = _real(label.get("score", 1.0))
            except (KeyError, TypeError, ValueError, OverflowError):
                raise FormatError(path, f"frame {index}: box2d needs numbers x1, y1, x2, y2 "
                                  "(and a numeric score)") from None
            _checked(path, f"frame {index}", index, (x1, y1, x2, y2), score)
            dets.append(Detection(box_px=(x1, y1, x2, y2), score=score, category=category))
    return out


def _real(value) -> float:
    """A JSON number as a float (booleans are not numbers)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(value)
    return float(value)


def _whole(value) -> int:
    """A JSON whole number (``7`` or ``7.0``) as an int."""
    v = _real(value)
    if v != int(v):
        raise ValueError(value)
    return int(v)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


# --------------------------------------------------------------------------- KITTI labels


@dataclass(frozen=True, slots=True)
class KittiLabel:
    """One object of a KITTI tracking ``label_02`` file (camera image_02).

    :param box_px: (x1, y1, x2, y2) [px]
    :param truncated: 0 (inside) .. 2 (heavily truncated) in tracking labels
    :param occluded: 0 visible, 1 partly, 2 largely occluded, 3 unknown
    :param size_hwl_m: 3D height, width, length [m]
    :param location_m: bottom centre of the 3D box, rectified camera frame (x right, y down,
        z forward) [m]
    """

    frame: int
    track_id: int
    type: str
    truncated: float
    occluded: int
    box_px: tuple[float, float, float, float]
    size_hwl_m: tuple[float, float, float]
    location_m: tuple[float, float, float]


def read_kitti_tracking_labels(path: Path) -> dict[int, list[KittiLabel]]:
    """Read a KITTI tracking ``label_02/SSSS.txt`` into frame -> labels (frames 0-based)."""
    out: dict[int, list[KittiLabel]] = {}
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise MissingInputError(path, "no such KITTI label file") from None
    for n, line in enumerate(lines, start=1):
        f = line.split()
        if not f:
            continue
        if len(f) < 17:
            raise FormatError(path, f"line {n}: expected 17 fields, got {len(f)}")
        v = [float(x) for x in f[3:17]]
        out.setdefault(int(f[0]), []).append(KittiLabel(
            frame=int(f[0]), track_id=int(f[1]), type=f[2], truncated=v[0],
            occluded=int(v[1]), box_px=(v[3], v[4], v[5], v[6]),
            size_hwl_m=(v[7], v[8], v[9]), location_m=(v[10], v[11], v[12])))
    return out


@dataclass(frozen=True, slots=True)
class MatchCounts:
    """Detections against KITTI labels in one or more frames (see :func:`score_against_kitti`)."""

    n_targets: int
    n_found: int
    n_detections: int
    n_false: int

    @property
    def recall(self) -> float:
        return self.n_found / self.n_targets if self.n_targets else float("nan")

    @property
    def precision(self) -> float:
        n = self.n_detections
        return (n - self.n_false) / n if n else float("nan")

    def __add__(self, other: MatchCounts) -> MatchCounts:
        return MatchCounts(self.n_targets + other.n_targets, self.n_found + other.n_found,
                           self.n_detections + other.n_detections,
                           self.n_false + other.n_false)


def is_kitti_target(label: KittiLabel, min_height_px: float = 25.0) -> bool:
    """The objects the recall bar counts: cars and vans, truncation < 0.5, occlusion <= 1,
    box height >= ``min_height_px``."""
    h = label.box_px[3] - label.box_px[1]
    return (label.type in ("Car", "Van") and label.truncated < 0.5 and label.occluded <= 1
            and h >= min_height_px)


def score_against_kitti(detections: list[Detection], labels: list[KittiLabel],
                        iou_threshold: float = 0.5, min_height_px: float = 25.0) -> MatchCounts:
    """Count recall and precision of one frame's detections against KITTI labels.

    Recall: targets (:func:`is_kitti_target`) matched one-to-one (Hungarian on IoU) by a
    detection with IoU >= ``iou_threshold``.

    Precision: a detection is *not* false if it overlaps (IoU >= ``iou_threshold``) any
    labelled vehicle of any difficulty (Car, Van, Truck, also heavily occluded or truncated
    ones, which the recall bar excludes but which are real vehicles), or lies mostly (>= 50%
    of its area) inside a DontCare region (areas the annotators did not label). Each
    vehicle label excuses at most one detection, so duplicate boxes on one car are false.
    """
    det_boxes = np.array([d.box_px for d in detections], dtype=float).reshape(-1, 4)
    targets = [lab for lab in labels if is_kitti_target(lab, min_height_px)]
    t_boxes = np.array([lab.box_px for lab in targets], dtype=float).reshape(-1, 4)
    pairs, _, _ = match(1.0 - iou_matrix(t_boxes, det_boxes), 1.0 - iou_threshold)
    n_found = len(pairs)

    vehicles = [lab for lab in labels if lab.type in ("Car", "Van", "Truck")]
    v_boxes = np.array([lab.box_px for lab in vehicles], dtype=float).reshape(-1, 4)
    pairs, _, unmatched = match(1.0 - iou_matrix(v_boxes, det_boxes), 1.0 - iou_threshold)
    dont_care = np.array([lab.box_px for lab in labels if lab.type == "DontCare"],
                         dtype=float).reshape(-1, 4)
    n_false = 0
    for j in unmatched:
        if not _mostly_inside(det_boxes[j], dont_care):
            n_false += 1
    return MatchCounts(n_targets=len(targets), n_found=n_found, n_detections=len(detections),
                       n_false=n_false)


def _mostly_inside(box: np.ndarray, regions: np.ndarray, fraction: float = 0.5) -> bool:
    if len(regions) == 0:
        return False
    ix = np.clip(np.minimum(box[2], regions[:, 2]) - np.maximum(box[0], regions[:, 0]), 0, None)
    iy = np.clip(np.minimum(box[3], regions[:, 3]) - np.maximum(box[1], regions[:, 1]), 0, None)
    area = max((box[2] - box[0]) * (box[3] - box[1]), 1e-9)
    return bool((ix * iy / area).max() >= fraction)

