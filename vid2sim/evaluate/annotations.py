"""Read annotated keyframes (Scalabel/BDD100K JSON, KITTI tracking label_02, CVAT for video XML,
KITTI raw tracklet XML).

Every reader returns :class:`~vid2sim.core.records.Keyframe` records on the scenario clock
(seconds from the video's first frame) holding vehicle boxes and ignore regions only.

Time base (where bugs hide, so spelled out):

- a frame number (KITTI ``frame``, Scalabel ``index``/``frameIndex``, CVAT ``frame``) is a
  0-based index into the video, ``t_s = frame / fps``;
- a Scalabel ``timestamp`` [ms] is taken relative to the file's first timestamp;
- with ``frame_names`` (the sorted file names of an image-folder "video"), a frame is matched
  to the image of the same name, or for KITTI to the image whose name carries its frame
  number (label frame 10 -> ``000010.png``); its video frame is then the image's POSITION in
  the folder, ``t_s = position / fps``. The three labelled images of KITTI tracking sequence
  0001 (frames 10, 15, 20) used as a 2 fps video thus become video frames 0, 1, 2 at
  0.0, 0.5, 1.0 s. Labelled frames without an image are dropped: there is nothing to replay
  them against.

Categories: vehicles are normalised to the project's names (car, truck, bus, motorcycle);
classes a simulated vehicle may legitimately sit on but that the scenario does not model
(KITTI Tram/Misc, BDD train/trailer/"other vehicle") and KITTI DontCare / crowd regions are
ignore regions; people and bicycles are dropped (the scenario holds vehicles only).
"""

from __future__ import annotations

import logging
import math
import re
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path
from typing import Any

from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    MissingInputError,
)
from vid2sim.base.fileio import check_input_size, parse_json
from vid2sim.core.records import AnnotatedBox, Keyframe, VehicleCategory
from vid2sim.evaluate.tracklet_keyframes import is_tracklet_xml, read_tracklet_keyframes

log = logging.getLogger(__name__)

KITTI_FPS = 10.0
"""Frame rate of KITTI's cameras [frames/s], used for label_02 when no ``fps`` is given."""

# Lower-cased source class -> (project category, ignore). Classes not listed are dropped.
_C = VehicleCategory
_CATEGORY_MAP: dict[str, tuple[VehicleCategory | str, bool]] = {
    # KITTI
    "car": (_C.CAR, False), "van": (_C.CAR, False), "truck": (_C.TRUCK, False),
    "tram": (_C.TRAM, True), "misc": ("misc", True), "dontcare": ("dontcare", True),
    # BDD100K / Scalabel / COCO-style names
    "bus": (_C.BUS, False), "motorcycle": (_C.MOTORCYCLE, False),
    "motor": (_C.MOTORCYCLE, False), "vehicle": (_C.CAR, False), "suv": (_C.CAR, False),
    "pickup": (_C.CAR, False),
    "train": ("train", True), "trailer": ("trailer", True),
    "other vehicle": ("other vehicle", True), "crowd": ("crowd", True),
}

# Classes dropped without a warning: they are annotated, just not vehicles.
_NOT_VEHICLES = {
    "pedestrian", "person", "person_sitting", "cyclist", "rider", "bicycle", "bike",
    "other person", "traffic light", "traffic sign", "drivable area", "lane",
}


def normalise_category(name: str) -> tuple[VehicleCategory | str, bool] | None:
    """Map a source class name to ``(category, ignore)``; None for a non-vehicle class."""
    key = " ".join(str(name).strip().lower().replace("-", " ").split())
    if key in _CATEGORY_MAP:
        return _CATEGORY_MAP[key]
    key_us = key.replace(" ", "_")
    if key_us in _CATEGORY_MAP:
        return _CATEGORY_MAP[key_us]
    return None


def read_keyframes(path: str | Path, *, fps: float | None = None,
                   frame_names: list[str] | None = None,
                   labelled_only: bool = False, calib_dir: Path | None = None,
                   rate_hz: float | None = None,
                   image_size_px: tuple[int, int] | None = None) -> list[Keyframe]:
    """Read annotated keyframes; the format is detected from the file's content.

    Parameters
    ----------
    path : str or Path
        Scalabel/BDD100K JSON, KITTI tracking ``label_02/SSSS.txt``, CVAT for video XML or
        a KITTI raw ``tracklet_labels.xml`` (:mod:`vid2sim.evaluate.tracklet_keyframes`).
    fps : float, optional
        Video frame rate [frames/s] that turns frame numbers into ``t_s``. Needed for frame
        numbers in Scalabel and CVAT files; KITTI defaults to 10 (its camera rate).
    frame_names : list of str, optional
        File names of the video's frames in order (an image folder used as a video); frames
        are matched to them by name (see the module docstring) and others dropped.
    labelled_only : bool
        Keep only frames carrying at least one vehicle box (not just ignore regions).
    calib_dir : Path, optional
        Tracklets only: the folder of the drive's ``calib_velo_to_cam.txt`` and
        ``calib_cam_to_cam.txt`` (default: the XML's own folder).
    rate_hz : float, optional
        Tracklets only: keyframes a second (default: every frame).
    image_size_px : (int, int), optional
        Tracklets only: the video's frame size, to which the projected boxes are clipped.

    Returns
    -------
    list of Keyframe
        Sorted by ``t_s``.

    Raises
    ------
    InputError
        Unreadable file, unknown format, malformed records, or times that cannot be derived.
    """
    path = Path(path)
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise ImpossibleValueError(path, f"fps {fps} must be a positive number")
    try:
        check_input_size(path, what="annotation")
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise MissingInputError(path, "no such annotation file") from None
    except IsADirectoryError:
        raise MissingInputError(path, "is a folder, expected an annotation file",
                                "give the JSON, XML or label_02 .txt file itself") from None
    except OSError as exc:
        raise MissingInputError(path, f"cannot read: {exc}") from None
    except UnicodeDecodeError as exc:
        raise FormatError(path, f"cannot read: {exc}") from None
    head = text.lstrip()[:1]
    if head in ("[", "{"):
        frames = _read_scalabel(text, path, fps, frame_names)
    elif head == "<" and is_tracklet_xml(text):
        frames = read_tracklet_keyframes(text, path, fps=KITTI_FPS if fps is None else fps,
                                         calib_dir=calib_dir, rate_hz=rate_hz,
                                         image_size_px=image_size_px)
    elif head == "<":
        frames = _read_cvat(text, path, fps, frame_names)
    elif head and head[0].isdigit():
        frames = _read_kitti(text, path, fps, frame_names)
    else:
        raise FormatError(path, "unknown annotation format",
                          "expected Scalabel/BDD100K JSON, KITTI label_02 text, CVAT XML or KITTI "
                          "tracklet XML")
    if labelled_only:
        frames = [k for k in frames if any(not b.ignore for b in k.boxes)]
    frames.sort(key=lambda k: (k.t_s, k.name))
    return frames


# --------------------------------------------------------------------------- frame names


def _trailing_number(name: str) -> int | None:
    """Frame number carried by a file name: ``000010.png`` -> 10, ``frame_12.jpg`` -> 12."""
    m = re.search(r"(\d+)(?:\.[A-Za-z0-9]+)?$", Path(str(name)).name)
    return int(m.group(1)) if m else None


class _FrameIndex:
    """Looks frames up in an image folder's ordered names (by name, or by number)."""

    def __init__(self, frame_names: list[str]):
        self.by_name: dict[str, int] = {}
        self.by_number: dict[int, int] = {}
        for pos, raw in enumerate(frame_names):
            name = Path(str(raw)).name
            self.by_name.setdefault(name, pos)
            self.by_name.setdefault(Path(name).stem, pos)
            number = _trailing_number(name)
            if number is not None:
                self.by_number.setdefault(number, pos)

    def position_of_name(self, name: str) -> int | None:
        base = Path(str(name)).name
        for key in (base, Path(base).stem):
            if key in self.by_name:
                return self.by_name[key]
        return None

    def position_of_number(self, number: int) -> int | None:
        return self.by_number.get(int(number))


def _need_fps(path: Path, fps: float | None, what: str) -> float:
    if fps is None:
        raise MissingInputError(path, f"{what} are frame numbers but no frame rate is known",
                                "pass --fps (video frames per second)")
    return fps


def _finite_box(vals: list[float], path: Path, where: str) -> tuple[float, float, float, float]:
    if len(vals) != 4 or not all(math.isfinite(v) for v in vals):
        raise ImpossibleValueError(path, f"{where}: box coordinates must be four finite numbers")
    x1, y1, x2, y2 = vals
    if x2 < x1 or y2 < y1:
        raise ImpossibleValueError(
            path, f"{where}: box has x2 < x1 or y2 < y1 ({x1}, {y1}, {x2}, {y2})")
    return (float(x1), float(y1), float(x2), float(y2))


# --------------------------------------------------------------------------- KITTI label_02


def _read_kitti(text: str, path: Path, fps: float | None,
                frame_names: list[str] | None) -> list[Keyframe]:
    """KITTI tracking ``label_02``: ``frame track_id type truncated occluded alpha x1 y1 x2
    y2 h w l X Y Z rotation_y [score]``, one object per line."""
    rate = KITTI_FPS if fps is None else fps
    index = _FrameIndex(frame_names) if frame_names is not None else None
    boxes_by_frame: dict[int, list[AnnotatedBox]] = defaultdict(list)
    unknown: set[str] = set()
    for lineno, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        if len(fields) not in (17, 18):
            raise FormatError(path, f"line {lineno}: expected 17 fields of KITTI label_02, "
                              f"got {len(fields)}")
        try:
            frame = int(fields[0])
            track_id = int(fields[1])
            nums = [float(v) for v in fields[3:17]]
        except ValueError:
            raise FormatError(path, f"line {lineno}: frame, track id or a value is not a number"
                              ) from None
        if frame < 0:
            raise ImpossibleValueError(path, f"line {lineno}: negative frame number {frame}")
        mapped = normalise_category(fields[2])
        if mapped is None:
            if fields[2].lower() not in _NOT_VEHICLES:
                unknown.add(fields[2])
            continue
        category, ignore = mapped
        box = _finite_box(nums[3:7], path, f"line {lineno}")
        h, w, length, _x_cam, _y_cam, z_cam, rot_y = nums[7:14]
        range_m = None
        # DontCare rows carry -1000 sizes and -10 positions: no 3D.
        if not ignore and min(h, w, length) > 0 and math.isfinite(z_cam):
            # X Y Z is the bottom centre in camera coordinates (Z forward); rotation_y turns
            # the box's length axis from camera +X towards -Z, so the box reaches
            # l/2|sin| + w/2|cos| towards the camera: Z minus that is the near face range.
            half_depth = 0.5 * length * abs(math.sin(rot_y)) + 0.5 * w * abs(math.cos(rot_y))
            range_m = z_cam - half_depth
        boxes_by_frame[frame].append(AnnotatedBox(
            box_px=box, category=category, id=None if track_id < 0 else str(track_id),
            range_m=range_m, ignore=ignore))
    if unknown:
        log.warning("%s: classes %s are not vehicles the scenario models; dropped",
                    path, ", ".join(sorted(unknown)))
    if not boxes_by_frame:
        raise FormatError(path, "no labelled objects found in this KITTI label file")
    out = []
    for frame, boxes in boxes_by_frame.items():
        name = f"{frame:06d}"
        if index is not None:
            pos = index.position_of_number(frame)
            if pos is None:
                continue
            out.append(Keyframe(frame=pos, t_s=pos / rate, name=name, boxes=boxes))
        else:
            out.append(Keyframe(frame=frame, t_s=frame / rate, name=name, boxes=boxes))
    if not out:
        raise InconsistentInputError(
            path, "none of the labelled frames has an image among the video's "
            "frames", "name images by KITTI frame number, e.g. 000010.png")
    return out


# --------------------------------------------------------------------------- Scalabel / BDD100K


def _read_scalabel(text: str, path: Path, fps: float | None,
                   frame_names: list[str] | None) -> list[Keyframe]:
    """Scalabel / BDD100K JSON: a list of frames or ``{"frames": [...]}``; each frame with
    ``name``, ``index`` (or ``frameIndex``) or ``timestamp`` [ms], and ``labels`` holding
    ``category``, ``box2d {x1, y1, x2, y2}``, optional ``id`` and ``attributes.crowd``."""
    data = parse_json(text, path)  # bad JSON, or nesting too deep, as an input error
    if isinstance(data, dict):
        if "frames" not in data:
            raise FormatError(path, "JSON object without 'frames'",
                              "expected Scalabel: a list of frames or {\"frames\": [...]}")
        data = data["frames"]
    if not isinstance(data, list):
        raise FormatError(path, "'frames' must be a list of frame objects")
    index = _FrameIndex(frame_names) if frame_names is not None else None
    timestamps = [f.get("timestamp") for f in data if isinstance(f, dict)
                  and isinstance(f.get("timestamp"), (int, float))
                  and not isinstance(f.get("timestamp"), bool)]
    t0_ms = min(timestamps) if timestamps else None
    out: list[Keyframe] = []
    unknown: set[str] = set()
    for i, fr in enumerate(data):
        where = f"frames[{i}]"
        if not isinstance(fr, dict):
            raise FormatError(path, f"{where}: expected an object")
        name = fr.get("name")
        name = str(name) if name is not None else None
        when = _scalabel_frame_time(fr, name, where, path, fps, index, t0_ms)
        if when is None:
            continue  # no image of that name: nothing to replay against
        video_frame, t_s = when
        boxes = _scalabel_boxes(fr, where, path, unknown)
        out.append(Keyframe(frame=video_frame, t_s=float(t_s),
                            name=name if name is not None else str(video_frame), boxes=boxes))
    if unknown:
        log.warning("%s: categories %s are not vehicles the scenario models; dropped",
                    path, ", ".join(sorted(unknown)))
    if not out:
        raise FormatError(path, "no frames found in this annotation file")
    return out


def _scalabel_frame_time(fr: dict, name: str | None, where: str, path: Path,
                         fps: float | None, index: _FrameIndex | None, t0_ms: float | None
                         ) -> tuple[int | None, float] | None:
    """A Scalabel frame's video frame and time [s] from its ``index``, else its ``timestamp``
    (from the file's first), else its name (looked up in the image folder, or the number it
    ends in); None for a name the image folder does not hold."""
    frame_no = fr.get("index", fr.get("frameIndex"))
    ts = fr.get("timestamp")
    if frame_no is not None:
        if isinstance(frame_no, bool) or not isinstance(frame_no, int) or frame_no < 0:
            raise FormatError(path, f"{where}.index: expected a non-negative integer")
        return frame_no, frame_no / _need_fps(path, fps, "frame indices")
    if ts is not None:
        if isinstance(ts, bool) or not isinstance(ts, (int, float)) or not math.isfinite(ts):
            raise FormatError(path, f"{where}.timestamp: expected a number of milliseconds")
        t_s = (ts - t0_ms) / 1000.0
        return (round(t_s * fps) if fps is not None else None), t_s
    if name is None:
        raise FormatError(path, f"{where}: frame has no name, index or timestamp")
    pos = index.position_of_name(name) if index is not None else None
    if index is not None and pos is None:
        return None
    if pos is None:
        # A name like "frame_000012.jpg" carries the frame number.
        pos = _trailing_number(name)
        if pos is None:
            raise FormatError(path, f"{where}: frame '{name}' has no index, timestamp "
                              "or frame number in its name",
                              "add 'index' to each frame or pass the frame names")
    return pos, pos / _need_fps(path, fps, "frame names")


def _scalabel_boxes(fr: dict, where: str, path: Path, unknown: set[str]) -> list[AnnotatedBox]:
    """The vehicle boxes of a Scalabel frame's ``labels`` (crowds as ignore regions); labels
    without a ``box2d`` are skipped, categories that are not vehicles added to ``unknown``."""
    labels = fr.get("labels") or []
    if not isinstance(labels, list):
        raise FormatError(path, f"{where}.labels: expected a list")
    boxes = []
    for j, lab in enumerate(labels):
        lw = f"{where}.labels[{j}]"
        if not isinstance(lab, dict):
            raise FormatError(path, f"{lw}: expected an object")
        box2d = lab.get("box2d")
        if box2d is None:
            continue  # polygons, lanes, drivable area: not boxes
        if not isinstance(box2d, dict) or not all(k in box2d for k in ("x1", "y1", "x2", "y2")):
            raise FormatError(path, f"{lw}.box2d: expected {{x1, y1, x2, y2}}")
        try:
            vals = [float(box2d[k]) for k in ("x1", "y1", "x2", "y2")]
        except (TypeError, ValueError):
            raise FormatError(path, f"{lw}.box2d: coordinates must be numbers") from None
        box = _finite_box(vals, path, lw)
        cat_name = str(lab.get("category", ""))
        mapped = normalise_category(cat_name)
        if mapped is None:
            if cat_name.lower() not in _NOT_VEHICLES:
                unknown.add(cat_name)
            continue
        category, ignore = mapped
        attrs = lab.get("attributes") or {}
        if isinstance(attrs, dict) and attrs.get("crowd") is True:
            ignore = True
        label_id = lab.get("id")
        boxes.append(AnnotatedBox(box_px=box, category=category,
                                  id=None if label_id is None else str(label_id),
                                  ignore=ignore))
    return boxes


# --------------------------------------------------------------------------- CVAT for video


def _read_cvat(text: str, path: Path, fps: float | None,
               frame_names: list[str] | None) -> list[Keyframe]:
    """CVAT for video XML 1.1: ``<track label=..><box frame= xtl= ytl= xbr= ybr= outside=
    keyframe=>``. Keyframes are the frames where an annotator drew or corrected a box
    (``keyframe="1"``, or every box where the attribute is absent); each holds every track
    visible there (``outside="0"``), interpolated boxes included. CVAT for images files
    (``<image name=..><box ..>``) are read too, one keyframe per image."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise FormatError(path, f"not well-formed XML: {exc}") from None
    if root.tag != "annotations":
        raise FormatError(path, f"XML root is <{root.tag}>, expected CVAT's <annotations>")
    boxes_by_frame: dict[int, list[AnnotatedBox]] = defaultdict(list)
    key_frames: set[int] = set()
    names: dict[int, str] = {}
    unknown: set[str] = set()
    _read_cvat_tracks(root, path, boxes_by_frame, key_frames, unknown)
    _read_cvat_images(root, path, boxes_by_frame, key_frames, names, unknown)
    if unknown:
        log.warning("%s: labels %s are not vehicles the scenario models; dropped",
                    path, ", ".join(sorted(unknown)))
    if not key_frames:
        raise FormatError(path, "no <track> boxes or <image> elements found",
                          "export the task as 'CVAT for video 1.1'")
    index = _FrameIndex(frame_names) if frame_names is not None else None
    out = []
    for frame in sorted(key_frames):
        name = names.get(frame, f"{frame:06d}")
        pos: int | None = frame
        if index is not None:
            pos = index.position_of_name(name) if frame in names else None
            if pos is None:
                pos = frame if frame < len(frame_names or []) else None
            if pos is None:
                continue
        rate = _need_fps(path, fps, "CVAT frames")
        out.append(Keyframe(frame=pos, t_s=pos / rate, name=name,
                            boxes=list(boxes_by_frame.get(frame, []))))
    if not out:
        raise InconsistentInputError(path, "none of the annotated frames is among the video's "
                                     "frames")
    return out


def _read_cvat_tracks(root: ET.Element, path: Path, boxes_by_frame: dict[int, list],
                      key_frames: set[int], unknown: set[str]) -> None:
    """CVAT for video: every visible box of every ``<track>`` into ``boxes_by_frame``; the
    frames where a box was drawn or corrected by hand into ``key_frames``."""
    for t_i, track in enumerate(root.iter("track")):
        label = track.attrib.get("label", "")
        track_id = track.attrib.get("id")
        for b_i, el in enumerate(track.iter("box")):
            where = f"track {track_id if track_id is not None else t_i} box {b_i}"
            frame = _cvat_frame(el, where, path)
            if el.attrib.get("outside", "0") == "1":
                continue
            if el.attrib.get("keyframe", "1") == "1":
                key_frames.add(frame)
            ab = _cvat_box(el, label, track_id, where, path, unknown)
            if ab is not None:
                boxes_by_frame[frame].append(ab)


def _read_cvat_images(root: ET.Element, path: Path, boxes_by_frame: dict[int, list],
                      key_frames: set[int], names: dict[int, str], unknown: set[str]) -> None:
    """CVAT for images: each ``<image>`` a keyframe of its boxes, named by its file."""
    for img in root.iter("image"):
        try:
            frame = int(img.attrib["id"])
        except (KeyError, ValueError):
            raise FormatError(path, "<image> without an integer id") from None
        key_frames.add(frame)
        names[frame] = img.attrib.get("name", str(frame))
        for b_i, el in enumerate(img.iter("box")):
            ab = _cvat_box(el, el.attrib.get("label", ""), None, f"image {frame} box {b_i}",
                           path, unknown)
            if ab is not None:
                boxes_by_frame[frame].append(ab)


def _cvat_box(el: ET.Element, label: str, track_id: str | None, where: str, path: Path,
              unknown: set[str]) -> AnnotatedBox | None:
    """A ``<box>`` as a vehicle box (None for a label that is not a vehicle's)."""
    try:
        vals = [float(el.attrib[k]) for k in ("xtl", "ytl", "xbr", "ybr")]
    except KeyError as exc:
        raise FormatError(path, f"{where}: <box> lacks {exc.args[0]}") from None
    except ValueError:
        raise FormatError(path, f"{where}: box coordinates must be numbers") from None
    box = _finite_box(vals, path, where)
    mapped = normalise_category(label)
    if mapped is None:
        if label.lower() not in _NOT_VEHICLES:
            unknown.add(label)
        return None
    return AnnotatedBox(box_px=box, category=mapped[0], id=track_id, ignore=mapped[1])


def _cvat_frame(el: ET.Element, where: str, path: Path) -> int:
    """A track ``<box>``'s frame number."""
    try:
        frame = int(el.attrib["frame"])
    except KeyError:
        raise FormatError(path, f"{where}: <box> lacks its frame") from None
    except ValueError:
        raise FormatError(path, f"{where}: frame is not an integer") from None
    if frame < 0:
        raise ImpossibleValueError(path, f"{where}: negative frame {frame}")
    return frame


def describe(keyframes: list[Keyframe]) -> dict[str, Any]:
    """Counts for a summary line: keyframes, vehicle boxes, ignore regions, time span [s]."""
    n_boxes = sum(1 for k in keyframes for b in k.boxes if not b.ignore)
    n_ignore = sum(1 for k in keyframes for b in k.boxes if b.ignore)
    span = (keyframes[0].t_s, keyframes[-1].t_s) if keyframes else (0.0, 0.0)
    return {"keyframes": len(keyframes), "boxes": n_boxes, "ignore_regions": n_ignore,
            "t_first_s": span[0], "t_last_s": span[1]}
