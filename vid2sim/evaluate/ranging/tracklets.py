"""Ranging truth from KITTI raw tracklets: lidar-annotated 3D boxes in the video's camera.

A KITTI raw drive's ``tracklet_labels.xml`` (boost serialization XML) holds one ``<item>`` per
object: its class, size ``h, w, l`` [m] and a pose per frame from ``first_frame`` on
(``tx, ty, tz``: the box's BOTTOM centre, ``rz``: yaw about the Velodyne's z axis, in the
Velodyne frame of that frame; ``occlusion``: 0 visible, 1 partly, 2 largely, -1 unknown;
``truncation``: 0 in the image, 1 truncated, 2 out of the image, 99 ignored).

Into the rectified camera 0 (the video's image_00): ``p_cam = R_rect_00 (R p_velo + T)``
with ``R, T`` from ``calib_velo_to_cam.txt`` and ``R_rect_00`` from ``calib_cam_to_cam.txt``;
pixels are ``P_rect_00 p_cam`` (Geiger et al., "Vision meets Robotics: The KITTI Dataset",
IJRR 2013, eq. 3-5; the devkit's readme for the tracklets' corner order).

Truth per frame and object (:func:`tracklet_truth`): the 8 corners in the camera frame, the
RANGE = depth of the nearest corner (what ``range_m`` of a car seen from behind is: its rear
face), the LATERAL offset of the centre (left positive, as ``lateral_m``), the world SPEED
from the OXTS ego motion (parked cars: 0), the RANGE RATE = central difference of the range
over +-2 frames, the projected 2D hull (a cuboid's hull: what an annotator's 3D box gives, not
what a detector's box hugs) and the flags.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.base.errors import FormatError, ImpossibleValueError, MissingInputError
from vid2sim.base.fileio import read_input_text
from vid2sim.core.camera import parse_kitti_calib

#: Pose fields of a tracklet frame read as numbers, in the array's column order.
POSE_FIELDS = ("tx", "ty", "tz", "rx", "ry", "rz")
#: Integer flags of a tracklet frame.
FLAG_FIELDS = ("state", "occlusion", "truncation")
#: A tracklet pose's position beyond this [m] from the lidar is not a road object (a
#: Velodyne HDL-64E sees 120 m).
MAX_POSITION_M = 500.0
#: Object sizes outside (0, this] [m] are impossible (a tram is at most 45 m long).
MAX_SIZE_M = 60.0
#: Corners nearer than this to the camera plane [m] are cut there before projection.
NEAR_PLANE_M = 0.1
#: Truth range rate: central difference over this many frames either side (+-2 frames at
#: 10 Hz: 0.4 s, which leaves the lidar labels' ~5 cm position noise at ~0.1 m/s).
RATE_HALF_WINDOW = 2
#: Truth speed: central difference of the world position over this many frames either side.
SPEED_HALF_WINDOW = 2


@dataclass(frozen=True)
class Tracklet:
    """One annotated object of a drive: class, size and per-frame pose in the Velodyne frame.

    ``pose``: (n, 6) tx, ty, tz (bottom centre), rx, ry, rz [m, rad]; ``flags``: (n, 3) state,
    occlusion, truncation; frame k of the pose is video frame ``first_frame + k``.
    """

    object_id: int
    object_type: str
    size_hwl_m: tuple[float, float, float]
    first_frame: int
    pose: np.ndarray
    flags: np.ndarray

    @property
    def frames(self) -> np.ndarray:
        return self.first_frame + np.arange(len(self.pose))


def _child_text(el: ET.Element, tag: str, path: Path, where: str) -> str:
    child = el.find(tag)
    if child is None or child.text is None:
        raise FormatError(path, f"{where}: no <{tag}>", "is this a KITTI tracklet_labels.xml?")
    return child.text.strip()


def _number(el: ET.Element, tag: str, path: Path, where: str) -> float:
    text = _child_text(el, tag, path, where)
    try:
        value = float(text)
    except ValueError:
        raise FormatError(path, f"{where}: <{tag}> is not a number ({text[:20]!r})",
                          "is this KITTI's tracklet_labels.xml?") from None
    if not math.isfinite(value):
        raise ImpossibleValueError(path, f"{where}: <{tag}> is {value}",
                                   "a tracklet's sizes and poses are finite numbers")
    return value


def _integer(el: ET.Element, tag: str, path: Path, where: str) -> int:
    value = _number(el, tag, path, where)
    if value != int(value):
        raise FormatError(path, f"{where}: <{tag}> must be a whole number, got {value}")
    return int(value)


def _read_poses(item: ET.Element, path: Path, where: str) -> tuple[np.ndarray, np.ndarray]:
    poses = item.find("poses")
    if poses is None:
        raise FormatError(path, f"{where}: no <poses>")
    rows = poses.findall("item")
    count = _integer(poses, "count", path, where + " <poses>")
    if count != len(rows):
        raise FormatError(path, f"{where}: <poses> says {count} poses but holds {len(rows)}")
    pose = np.zeros((len(rows), len(POSE_FIELDS)))
    flags = np.zeros((len(rows), len(FLAG_FIELDS)), dtype=int)
    for k, row in enumerate(rows):
        w = f"{where} pose {k}"
        pose[k] = [_number(row, tag, path, w) for tag in POSE_FIELDS]
        flags[k] = [_integer(row, tag, path, w) for tag in FLAG_FIELDS]
    if np.any(np.abs(pose[:, :3]) > MAX_POSITION_M):
        raise ImpossibleValueError(path, f"{where}: a position lies more than "
                                   f"{MAX_POSITION_M:g} m from the lidar")
    return pose, flags


def parse_tracklets(text: str, path: Path) -> list[Tracklet]:
    """The tracklets of a ``tracklet_labels.xml`` text (see the module docstring).

    Raises :class:`FormatError` for XML that is not a tracklet file (or whose counts do not
    match what it holds) and :class:`ImpossibleValueError` for non-finite or impossible
    sizes, positions and frames.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise FormatError(path, f"not well-formed XML: {exc}") from None
    tracklets = root if root.tag == "tracklets" else root.find("tracklets")
    if tracklets is None:
        raise FormatError(path, f"XML root <{root.tag}> holds no <tracklets>",
                          "expected KITTI raw's tracklet_labels.xml")
    items = tracklets.findall("item")
    count = _integer(tracklets, "count", path, "<tracklets>")
    if count != len(items):
        raise FormatError(path, f"<tracklets> says {count} objects but holds {len(items)}")
    out = []
    for i, item in enumerate(items):
        where = f"object {i}"
        size = tuple(_number(item, tag, path, where) for tag in ("h", "w", "l"))
        if not all(0 < s <= MAX_SIZE_M for s in size):
            raise ImpossibleValueError(path, f"{where}: size h, w, l = {size} m")
        first = _integer(item, "first_frame", path, where)
        if first < 0:
            raise ImpossibleValueError(path, f"{where}: negative first_frame {first}")
        pose, flags = _read_poses(item, path, where)
        out.append(Tracklet(i, _child_text(item, "objectType", path, where), size, first,
                            pose, flags))
    return out


def read_tracklets(path: str | Path) -> list[Tracklet]:
    """The tracklets of a KITTI raw ``tracklet_labels.xml`` file."""
    path = Path(path)
    return parse_tracklets(read_input_text(path), path)


# --------------------------------------------------------------------------- calibration


@dataclass(frozen=True)
class RawCalibration:
    """Velodyne -> rectified camera 0 of a KITTI raw drive.

    ``p_cam = r_rect (r_velo p_velo + t_velo)``; pixels ``p_rect @ [p_cam, 1]``.
    """

    r_velo: np.ndarray
    t_velo: np.ndarray
    r_rect: np.ndarray
    p_rect: np.ndarray

    def velo_to_cam(self, points_velo_m: np.ndarray) -> np.ndarray:
        """(N, 3) Velodyne points -> (N, 3) rectified camera points [m] (x right, y down, z
        forward)."""
        p = np.asarray(points_velo_m, dtype=float).reshape(-1, 3)
        return (p @ self.r_velo.T + self.t_velo) @ self.r_rect.T

    def project(self, points_cam_m: np.ndarray) -> np.ndarray:
        """(N, 3) camera points in front of the camera -> (N, 2) pixels."""
        p = np.asarray(points_cam_m, dtype=float).reshape(-1, 3)
        h = np.column_stack((p, np.ones(len(p)))) @ self.p_rect.T
        return h[:, :2] / h[:, 2:3]


def _calib_matrix(values: dict[str, np.ndarray], key: str, shape: tuple[int, int],
                  path: Path) -> np.ndarray:
    v = values.get(key)
    if v is None or v.size != shape[0] * shape[1]:
        raise FormatError(path, f"no {key} of {shape[0] * shape[1]} numbers",
                          "expected KITTI raw calibration files")
    if not np.all(np.isfinite(v)):
        raise ImpossibleValueError(path, f"{key} holds non-finite numbers")
    return v.reshape(shape)


def read_raw_calibration(velo_to_cam: str | Path, cam_to_cam: str | Path,
                         camera: int = 0) -> RawCalibration:
    """Read ``calib_velo_to_cam.txt`` (R, T) and ``calib_cam_to_cam.txt`` (R_rect_0N,
    P_rect_0N) of a KITTI raw drive; ``camera`` N (0: the left grey camera)."""
    v_path, c_path = Path(velo_to_cam), Path(cam_to_cam)
    for p in (v_path, c_path):
        if not p.is_file():
            raise MissingInputError(p, "no such calibration file",
                                    "KITTI raw's calib_velo_to_cam.txt and calib_cam_to_cam.txt")
    v = parse_kitti_calib(read_input_text(v_path))
    c = parse_kitti_calib(read_input_text(c_path))
    return RawCalibration(_calib_matrix(v, "R", (3, 3), v_path),
                          _calib_matrix(v, "T", (1, 3), v_path)[0],
                          _calib_matrix(c, f"R_rect_{camera:02d}", (3, 3), c_path),
                          _calib_matrix(c, f"P_rect_{camera:02d}", (3, 4), c_path))


def calibration_beside(xml_path: str | Path, calib_dir: str | Path | None = None
                       ) -> RawCalibration:
    """The calibration of a tracklet file: ``calib_velo_to_cam.txt`` and
    ``calib_cam_to_cam.txt`` in ``calib_dir`` (default: the XML's own folder)."""
    folder = Path(calib_dir) if calib_dir is not None else Path(xml_path).parent
    return read_raw_calibration(folder / "calib_velo_to_cam.txt",
                                folder / "calib_cam_to_cam.txt")


# --------------------------------------------------------------------------- geometry


def box_corners_velo(size_hwl_m: tuple[float, float, float], pose: np.ndarray) -> np.ndarray:
    """(8, 3) corners of a tracklet box in the Velodyne frame: bottom face first (front-left,
    front-right, rear-right, rear-left as the devkit orders them), then the top face; ``pose``
    one row (tx, ty, tz, rx, ry, rz) with the bottom centre at (tx, ty, tz) and yaw rz."""
    h, w, length = size_hwl_m
    x = np.array([1, 1, -1, -1, 1, 1, -1, -1]) * length / 2
    y = np.array([1, -1, -1, 1, 1, -1, -1, 1]) * w / 2
    z = np.array([0, 0, 0, 0, 1, 1, 1, 1]) * h
    c, s = math.cos(pose[5]), math.sin(pose[5])
    return np.column_stack((c * x - s * y + pose[0], s * x + c * y + pose[1], z + pose[2]))


_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4),
          (0, 4), (1, 5), (2, 6), (3, 7))


def hull_box_px(corners_cam_m: np.ndarray, calib: RawCalibration, width_px: int,
                height_px: int, near_m: float = NEAR_PLANE_M
                ) -> tuple[tuple[float, float, float, float] | None, float, bool, float]:
    """Pixel box of a 3D box's projection, cut at a near plane where it reaches behind it.

    Returns ``(box, in_image_fraction, bottom_cut, side_margin_px)``: the hull clipped to the
    image (None when nothing of it is in view), the share of the unclipped hull inside the
    image, whether the hull's lowest row lies below the image's last row (its ground contact
    not in view), and how far the unclipped hull stays inside the left and right borders
    (negative: beyond one).
    """
    depth = corners_cam_m[:, 2]
    front = depth > near_m
    if not front.any():
        return None, 0.0, False, -math.inf
    pts = [corners_cam_m[front]]
    for i, j in _EDGES:
        if front[i] != front[j]:
            s = (near_m - depth[i]) / (depth[j] - depth[i])
            pts.append((corners_cam_m[i] + s * (corners_cam_m[j] - corners_cam_m[i]))[None])
    uv = calib.project(np.vstack(pts))
    x1, y1 = uv.min(axis=0)
    x2, y2 = uv.max(axis=0)
    w, h = width_px - 1, height_px - 1
    margin = float(min(x1, w - x2)) if front.all() else -math.inf
    if x2 <= 0 or y2 <= 0 or x1 >= w or y1 >= h:
        return None, 0.0, False, margin
    area = max((x2 - x1) * (y2 - y1), 1e-9)
    cx1, cx2 = float(np.clip(x1, 0, w)), float(np.clip(x2, 0, w))
    cy1, cy2 = float(np.clip(y1, 0, h)), float(np.clip(y2, 0, h))
    if cx2 - cx1 < 1.0 or cy2 - cy1 < 1.0:
        return None, 0.0, False, margin
    return ((cx1, cy1, cx2, cy2), float((cx2 - cx1) * (cy2 - cy1) / area), bool(y2 > h),
            margin)


def central_difference(frames: np.ndarray, values: np.ndarray, half: int, dt_s: float
                       ) -> np.ndarray:
    """d(values)/dt at each frame from ``(v[k + half] - v[k - half]) / (2 half dt)`` where
    both neighbours exist (consecutive frame numbers), else NaN; ``values`` may be (N,) or
    (N, D)."""
    frames = np.asarray(frames)
    v = np.asarray(values, dtype=float)
    out = np.full(v.shape, np.nan)
    pos = {int(f): i for i, f in enumerate(frames)}
    for i, f in enumerate(frames):
        a, b = pos.get(int(f) - half), pos.get(int(f) + half)
        if a is not None and b is not None:
            out[i] = (v[b] - v[a]) / (2 * half * dt_s)
    return out


# --------------------------------------------------------------------------- truth table

#: A tracklet whose world speed stays below this [m/s] is standing (parked); KITTI raw
#: 0001's parked cars read 0.0-0.3 m/s from the lidar poses and OXTS, the tram 8-9 m/s.
PARKED_MAX_SPEED_MPS = 1.0


@dataclass
class TrackletTruth:
    """Per (frame, object) truth of a drive, as columns (see :func:`tracklet_truth`).

    ``range_m``: depth of the box's nearest corner in the camera frame; ``lateral_m``: its
    centre's offset, left positive; ``ground_z_m``: height of its bottom face relative to the
    road under the camera (camera height minus the bottom's depth below the camera);
    ``box_px``: (N, 4) projected hull in the image (NaN: not in view); ``bottom_cut``: the
    hull's lowest row is below the image; ``side_margin_px``: how far the unclipped hull stays
    inside the side borders; ``speed_mps``: world speed (NaN without ego
    motion); ``range_rate_mps``: central difference of ``range_m`` over +-2 frames;
    ``parked``: the object's median speed below :data:`PARKED_MAX_SPEED_MPS`.
    """

    frame: np.ndarray
    object_id: np.ndarray
    object_type: np.ndarray
    range_m: np.ndarray
    lateral_m: np.ndarray
    ground_z_m: np.ndarray
    box_px: np.ndarray
    in_image: np.ndarray
    bottom_cut: np.ndarray
    side_margin_px: np.ndarray
    occlusion: np.ndarray
    truncation: np.ndarray
    speed_mps: np.ndarray
    range_rate_mps: np.ndarray
    parked: np.ndarray

    def __len__(self) -> int:
        return len(self.frame)

    def at_frame(self, frame: int) -> np.ndarray:
        """Row indices of one frame's objects."""
        return np.flatnonzero(self.frame == frame)


def _world_speed(frames: np.ndarray, centre_veh: np.ndarray, motion, dt_s: float
                 ) -> np.ndarray:
    """World speed [m/s] of an object from its (x forward, y left) centres relative to the
    camera and the camera's planar pose (:class:`vid2sim.evaluate.ranging.static.EgoMotion`)."""
    k = np.clip(frames, 0, len(motion.yaw_rad) - 1)
    c, s = np.cos(motion.yaw_rad[k]), np.sin(motion.yaw_rad[k])
    world = motion.xy_m[k] + np.column_stack((c * centre_veh[:, 0] - s * centre_veh[:, 1],
                                              s * centre_veh[:, 0] + c * centre_veh[:, 1]))
    vel = central_difference(frames, world, SPEED_HALF_WINDOW, dt_s)
    return np.hypot(vel[:, 0], vel[:, 1])


def _object_rows(t: Tracklet, calib: RawCalibration, size_px: tuple[int, int],
                 camera_height_m: float, motion, dt_s: float, n_frames: int | None
                 ) -> dict[str, np.ndarray]:
    frames = t.frames
    keep = frames < n_frames if n_frames is not None else np.ones(len(frames), bool)
    frames, pose, flags = frames[keep], t.pose[keep], t.flags[keep]
    corners = np.stack([calib.velo_to_cam(box_corners_velo(t.size_hwl_m, p)) for p in pose]
                       ) if len(pose) else np.zeros((0, 8, 3))
    rng = corners[:, :, 2].min(axis=1) if len(pose) else np.zeros(0)
    centre = corners.mean(axis=1) if len(pose) else np.zeros((0, 3))
    views = [hull_box_px(c, calib, *size_px) for c in corners]
    box = np.array([v[0] if v[0] is not None else (np.nan,) * 4 for v in views]).reshape(-1, 4)
    speed = (_world_speed(frames, np.column_stack((centre[:, 2], -centre[:, 0])), motion, dt_s)
             if motion is not None and len(frames) else np.full(len(frames), np.nan))
    parked = bool(np.nanmedian(speed) < PARKED_MAX_SPEED_MPS) if np.isfinite(speed).any() \
        else False
    return {"frame": frames, "object_id": np.full(len(frames), t.object_id),
            "object_type": np.array([t.object_type] * len(frames), dtype=object),
            "range_m": rng, "lateral_m": -centre[:, 0],
            # the bottom face is 4 corners at y_cam = its depth below the camera
            "ground_z_m": camera_height_m - corners[:, :4, 1].mean(axis=1),
            "box_px": box, "in_image": np.array([v[1] for v in views]),
            "bottom_cut": np.array([v[2] for v in views], dtype=bool),
            "side_margin_px": np.array([v[3] for v in views], dtype=float),
            "occlusion": flags[:, 1], "truncation": flags[:, 2], "speed_mps": speed,
            "range_rate_mps": central_difference(frames, rng, RATE_HALF_WINDOW, dt_s),
            "parked": np.full(len(frames), parked)}


def tracklet_truth(tracklets: list[Tracklet], calib: RawCalibration, image_size_px: tuple[int, int],
                   *, camera_height_m: float, fps: float, motion=None,
                   n_frames: int | None = None) -> TrackletTruth:
    """Truth of every tracklet pose in the video's camera (see :class:`TrackletTruth`).

    ``image_size_px``: (width, height) of the video's frames (the hull is clipped to them);
    ``fps``: the video's frame rate: rates are per VIDEO second, the pipeline's time base
    (frame / fps), so a comparison measures ranging rather than the file's frame clock;
    ``motion``: the drive's ego motion (:func:`vid2sim.evaluate.ranging.static.ego_motion`)
    for world speeds; ``n_frames``: poses on later frames are dropped.
    """
    if not (math.isfinite(fps) and fps > 0):
        raise ImpossibleValueError(None, f"frame rate {fps} must be positive")
    parts = [_object_rows(t, calib, image_size_px, camera_height_m, motion, 1.0 / fps,
                          n_frames) for t in tracklets]
    if not parts:
        empty = np.zeros(0)
        return TrackletTruth(*(empty,) * 6, np.zeros((0, 4)), *(empty,) * 8)
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    order = np.lexsort((cols["object_id"], cols["frame"]))
    return TrackletTruth(**{k: v[order] for k, v in cols.items()})
