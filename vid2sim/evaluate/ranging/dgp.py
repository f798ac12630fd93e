"""Reader of TRI's DGP scene format (camera frames with lidar-annotated 3D cuboids) and the
ranging truth it gives: the ground from the cuboids, a camera on it, each cuboid's range.

A DGP scene folder holds ``scene_<hash>.json`` (samples of datums: per sensor and time, its
file and annotation files), ``calibration/<key>.json`` (per sensor intrinsics and extrinsics),
``ontology/<key>.json`` (class ids and names) and, per camera datum, the image
(``rgb/<CAMERA>/<t>.jpg``), its 3D cuboids (``bounding_box_3d/<CAMERA>/<t>.json``, in the
camera frame: x right, y down, z forward) and its 2D boxes (``bounding_box_2d/...``), linked by
``instance_id``. Annotation type 0 is 2D boxes and 1 is 3D boxes (DGP's ``AnnotationType``).
Only the camera asked for is read; datums whose files are absent are skipped, malformed files
raise :class:`~vid2sim.base.errors.InputError`.

The truth: the cuboids are annotated on lidar, so their bottoms say where the road is. The
camera of a frame is the one whose road plane is the least-squares plane through the bottoms
of the cars nearer than :data:`GROUND_MAX_RANGE_M` (the camera frame may be pitched against
the road, and the road may rise: take the ground from the cuboids, not a flat-road guess). A
vehicle's range is the x of its nearest end in that camera's vehicle frame (the rear face of
a vehicle driving ahead), its lateral offset the y of its centre.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path

import numpy as np

from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    MissingInputError,
)
from vid2sim.base.fileio import read_input_text
from vid2sim.core.camera import Camera, PitchSource

ANNOTATION_2D, ANNOTATION_3D = "0", "1"
# The ground plane is fitted to cars nearer than this [m]: beyond it one lidar return in a
# hundred falls on a far car, and the road may bend (in scene_01 the bottoms lie 1.18 m below
# the camera at 9 m, 0.7 m at 44-60 m and 0.1 m at 65-70 m).
GROUND_MAX_RANGE_M = 50.0
# A fitted ground whose car bottoms scatter more than this about it [m] is no plane.
GROUND_MAX_RMS_M = 0.25


def quaternion_to_matrix(qw: float, qx: float, qy: float, qz: float) -> np.ndarray:
    """3x3 rotation of a unit quaternion (Hamilton convention, w first; normalised here)."""
    q = np.array([qw, qx, qy, qz], dtype=float)
    norm = float(np.linalg.norm(q))
    if not math.isfinite(norm) or norm < 1e-9:
        raise ValueError(f"not a rotation quaternion: {q.tolist()}")
    w, x, y, z = q / norm
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@dataclass(frozen=True)
class DgpCuboid:
    """One 3D box of a camera datum, in the camera frame (x right, y down, z forward) [m].

    ``rotation`` maps the box's own axes (x along its length, y across, z up) to the camera
    frame; ``center_m`` is the box's centre.
    """

    instance_id: int
    class_name: str
    center_m: tuple[float, float, float]
    rotation: tuple[tuple[float, float, float], ...]
    length_m: float
    width_m: float
    height_m: float
    num_points: int
    occlusion: int
    truncation: float

    def corners_m(self) -> np.ndarray:
        """(8, 3) corners in the camera frame; rows 0-3 the bottom face."""
        half = np.array([[sx * self.length_m, sy * self.width_m, sz * self.height_m]
                         for sz in (-0.5, 0.5) for sx in (-0.5, 0.5) for sy in (-0.5, 0.5)])
        return half @ np.asarray(self.rotation).T + np.asarray(self.center_m)

    def bottom_center_m(self) -> np.ndarray:
        """Centre of the bottom face in the camera frame [m]."""
        up = np.asarray(self.rotation)[:, 2]
        return np.asarray(self.center_m) - 0.5 * self.height_m * up


@dataclass(frozen=True)
class DgpBox2d:
    """One 2D box of a camera datum: (x1, y1, x2, y2) [px]."""

    instance_id: int
    class_name: str
    box_px: tuple[float, float, float, float]


@dataclass(frozen=True)
class DgpFrame:
    """One camera image of a scene with its intrinsics and annotations."""

    scene: str
    t_s: float
    image: Path
    width_px: int
    height_px: int
    fx: float
    fy: float
    cx: float
    cy: float
    cuboids: tuple[DgpCuboid, ...]
    boxes_2d: tuple[DgpBox2d, ...]
    #: the camera's pose in the vehicle frame (x forward, y left, z up): rotation camera ->
    #: vehicle and position [m] (DGP calibration extrinsics)
    extrinsic_rotation: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0),
                                                                  (0.0, 1.0, 0.0),
                                                                  (0.0, 0.0, 1.0))
    extrinsic_translation_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


def _load_json(path: Path) -> object:
    text = read_input_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(path, f"not JSON: {exc.msg} at line {exc.lineno}") from None


def _num(value: object, path: Path, what: str, positive: bool = False) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise FormatError(path, f"{what} is not a number: {value!r}") from None
    if not math.isfinite(v) or (positive and v <= 0):
        raise ImpossibleValueError(
            path, f"{what} must be {'positive and ' if positive else ''}finite, "
            f"got {v}")
    return v


def _ontology(path: Path) -> dict[int, str]:
    doc = _load_json(path)
    try:
        return {int(item["id"]): str(item["name"]) for item in doc["items"]}  # type: ignore
    except (KeyError, TypeError, ValueError):
        raise FormatError(path, "ontology lacks items with id and name") from None


def read_cuboids(path: Path, names: dict[int, str]) -> tuple[DgpCuboid, ...]:
    """The 3D boxes of one ``bounding_box_3d`` file (class names from ``names``)."""
    doc = _load_json(path)
    out = []
    try:
        items = doc["annotations"]  # type: ignore[index]
        for a in items:
            box = a["box"]
            pose = box["pose"]
            t, q = pose["translation"], pose["rotation"]
            rot = quaternion_to_matrix(*(_num(q[k], path, f"rotation {k}")
                                         for k in ("qw", "qx", "qy", "qz")))
            out.append(DgpCuboid(
                instance_id=int(a.get("instance_id", -1)),
                class_name=names.get(int(a["class_id"]), f"class {a['class_id']}"),
                center_m=tuple(_num(t[k], path, f"translation {k}") for k in "xyz"),
                rotation=tuple(tuple(float(v) for v in row) for row in rot),
                length_m=_num(box["length"], path, "length", positive=True),
                width_m=_num(box["width"], path, "width", positive=True),
                height_m=_num(box["height"], path, "height", positive=True),
                num_points=int(a.get("num_points", 0)),
                occlusion=int(box.get("occlusion", 0)),
                truncation=_num(box.get("truncation", 0.0), path, "truncation")))
    except (KeyError, TypeError) as exc:
        raise FormatError(path, f"a 3D box lacks {exc}", "is this a DGP bounding_box_3d file?"
                          ) from None
    except ValueError as exc:
        raise ImpossibleValueError(path, str(exc)) from None
    return tuple(out)


def read_boxes_2d(path: Path, names: dict[int, str]) -> tuple[DgpBox2d, ...]:
    """The 2D boxes of one ``bounding_box_2d`` file (x, y, w, h -> x1, y1, x2, y2)."""
    doc = _load_json(path)
    out = []
    try:
        for a in doc["annotations"]:  # type: ignore[index]
            b = a["box"]
            x, y = _num(b["x"], path, "x"), _num(b["y"], path, "y")
            w, h = _num(b["w"], path, "w", positive=True), _num(b["h"], path, "h", positive=True)
            out.append(DgpBox2d(int(a.get("instance_id", -1)),
                                names.get(int(a["class_id"]), f"class {a['class_id']}"),
                                (x, y, x + w, y + h)))
    except (KeyError, TypeError) as exc:
        raise FormatError(path, f"a 2D box lacks {exc}", "is this a DGP bounding_box_2d file?"
                          ) from None
    return tuple(out)


def _timestamp_s(text: str, path: Path) -> float:
    try:
        return datetime.fromisoformat(text).timestamp()
    except (ValueError, AttributeError):
        raise FormatError(path, f"timestamp {text!r} is not ISO 8601") from None


def read_dgp_scene(scene_dir: Path, camera: str = "CAMERA_01") -> list[DgpFrame]:
    """All frames of one camera in a DGP scene folder, in time order.

    Raises
    ------
    InputError
        If the folder holds no (or several) ``scene_*.json``, the camera is not calibrated,
        or a file is malformed.
    """
    scene_dir = Path(scene_dir)
    scenes = sorted(scene_dir.glob("scene_*.json"))
    if len(scenes) != 1:
        raise MissingInputError(scene_dir, f"{len(scenes)} scene_*.json files (one expected)",
                                "point at one DGP scene folder")
    doc = _load_json(scenes[0])
    try:
        ontologies = doc["ontologies"]  # type: ignore[index]
        samples = doc["samples"]  # type: ignore[index]
        datums = {d["key"]: d for d in doc["data"]}  # type: ignore[index]
    except (KeyError, TypeError) as exc:
        raise FormatError(scenes[0], f"not a DGP scene: lacks {exc}") from None
    names = {k: _ontology(scene_dir / "ontology" / f"{v}.json") for k, v in ontologies.items()}
    frames: list[DgpFrame] = []
    for sample in samples:
        calib_path = scene_dir / "calibration" / f"{sample['calibration_key']}.json"
        calib = _load_json(calib_path)
        try:
            index = calib["names"].index(camera)  # type: ignore[index]
            intr = calib["intrinsics"][index]  # type: ignore[index]
            ext = calib["extrinsics"][index]  # type: ignore[index]
            ext_t = tuple(_num(ext["translation"][k], calib_path, f"translation {k}")
                          for k in "xyz")
            ext_r = quaternion_to_matrix(*(_num(ext["rotation"][k], calib_path, f"rotation {k}")
                                           for k in ("qw", "qx", "qy", "qz")))
        except (KeyError, ValueError, TypeError, IndexError):
            raise FormatError(calib_path, f"no calibration of {camera}",
                              "needs names, intrinsics and extrinsics per sensor") from None
        for key in sample["datum_keys"]:
            datum = datums.get(key)
            if datum is None or datum["id"]["name"] != camera or "image" not in datum["datum"]:
                continue
            img = datum["datum"]["image"]
            image = scene_dir / img["filename"]
            ann = img.get("annotations", {})
            if not image.exists() or ANNOTATION_3D not in ann:
                continue
            cuboids = read_cuboids(scene_dir / ann[ANNOTATION_3D], names.get(ANNOTATION_3D, {}))
            boxes = (read_boxes_2d(scene_dir / ann[ANNOTATION_2D], names.get(ANNOTATION_2D, {}))
                     if ANNOTATION_2D in ann and (scene_dir / ann[ANNOTATION_2D]).exists()
                     else ())
            frames.append(DgpFrame(
                scene=scene_dir.name, t_s=_timestamp_s(datum["id"]["timestamp"], scenes[0]),
                image=image, width_px=int(img["width"]), height_px=int(img["height"]),
                fx=_num(intr["fx"], calib_path, "fx", True),
                fy=_num(intr["fy"], calib_path, "fy", True),
                cx=_num(intr["cx"], calib_path, "cx"), cy=_num(intr["cy"], calib_path, "cy"),
                cuboids=cuboids, boxes_2d=boxes,
                extrinsic_rotation=tuple(tuple(float(v) for v in row) for row in ext_r),
                extrinsic_translation_m=ext_t))
    return sorted(frames, key=lambda f: f.t_s)


# --------------------------------------------------------------------------- ground and truth


def fit_ground_plane(points_m: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares plane through (N >= 3) points in a camera frame (y down).

    Returns the plane's unit normal pointing up (towards the camera side, negative y), the
    camera's height above the plane [m] and the RMS distance of the points from it [m].
    """
    p = np.asarray(points_m, dtype=float).reshape(-1, 3)
    if len(p) < 3:
        raise ValueError(f"a plane needs 3 points, got {len(p)}")
    centroid = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - centroid)
    n = vt[2]
    if n[1] > 0:
        n = -n
    height = -float(np.dot(n, centroid))  # the camera is at the origin, above the plane
    rms = float(np.sqrt(np.mean(((p - centroid) @ n) ** 2)))
    return n, height, rms


def camera_on_plane(frame: DgpFrame, normal_up: np.ndarray, height_m: float) -> Camera:
    """The project's camera (intrinsics of the frame, no distortion) mounted ``height_m``
    above the road plane whose upward normal in the camera frame is ``normal_up``: its pitch
    and roll put the vehicle frame's z axis along the normal; yaw 0 (the vehicle's x is the
    optical axis laid on the road)."""
    n = np.asarray(normal_up, dtype=float)
    n = n / np.linalg.norm(n)
    base = Camera(image_width=frame.width_px, image_height=frame.height_px, fx=frame.fx,
                  fy=frame.fy, cx=frame.cx, cy=frame.cy, height_m=float(height_m),
                  assumptions=(f"DGP {frame.scene}: ground plane fitted to the lidar cuboids",),
                  pitch_source=PitchSource.CALIBRATION)
    # Vehicle up in camera coordinates is R^T e_z; with R = Ry(pitch) Rx(roll) B that is
    # (-sin(roll) cos(pitch), -cos(roll) cos(pitch), -sin(pitch)) (x right, y down, z fwd):
    # a camera pitched down sees the up axis tilt towards -z.
    pitch = math.degrees(math.asin(float(np.clip(-n[2], -1.0, 1.0))))
    roll = math.degrees(math.atan2(-n[0], -n[1]))
    return replace(base, pitch_deg=pitch, roll_deg=roll)


def calibration_camera(frame: DgpFrame) -> Camera:
    """The frame's camera from the calibration's extrinsics alone: its height above the
    vehicle frame's origin (which lies on the ground: in scene_01 the plane of the cuboids
    puts the camera 1.40 m high where the extrinsics say 1.36 m, and pitches it 0.71 deg
    down where they say 0.64 deg) and the pitch and roll of its axes in that frame."""
    up_cam = np.asarray(frame.extrinsic_rotation)[2]  # vehicle z in camera coordinates
    return camera_on_plane(frame, up_cam, float(frame.extrinsic_translation_m[2]))


def ground_camera(frame: DgpFrame, max_range_m: float = GROUND_MAX_RANGE_M,
                  classes: tuple[str, ...] = ("Car",)) -> tuple[Camera, float, int]:
    """The frame's camera on the ground of its cuboids (see the module docstring), the RMS
    scatter of the car bottoms about that ground [m] and how many cars made it.

    Raises
    ------
    InputError
        If fewer than three cars lie within ``max_range_m`` or they scatter about the plane by
        more than :data:`GROUND_MAX_RMS_M`.
    """
    bottoms = np.array([c.bottom_center_m() for c in frame.cuboids
                        if c.class_name in classes and 0 < c.center_m[2] < max_range_m])
    if len(bottoms) < 3:
        raise InconsistentInputError(
            frame.image, f"{len(bottoms)} cars within {max_range_m:g} m: too few "
            "to know the ground")
    normal, height, rms = fit_ground_plane(bottoms)
    if rms > GROUND_MAX_RMS_M:
        raise InconsistentInputError(
            frame.image, f"the cars' bottoms scatter {rms:.2f} m about a plane")
    return camera_on_plane(frame, normal, height), rms, len(bottoms)


def cuboid_range_m(cuboid: DgpCuboid, camera: Camera) -> tuple[float, float]:
    """(range, lateral) of a cuboid in the camera's vehicle frame [m]: the x of its nearest
    corner (the rear face of a car driving ahead) and the y of its centre."""
    r = camera.R_veh_from_cam
    corners = cuboid.corners_m() @ r.T + camera.position_veh_m
    centre = np.asarray(cuboid.center_m) @ r.T + camera.position_veh_m
    return float(corners[:, 0].min()), float(centre[1])
