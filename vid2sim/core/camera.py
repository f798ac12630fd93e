"""Pinhole camera with OpenCV distortion, mounted on the ego vehicle: projection and ground rays.

Frames:
- vehicle frame: x forward, y left, z up [m]; origin on the road directly below the camera,
  so the camera centre is at (0, 0, ``height_m``);
- camera frame (OpenCV): x right, y down, z along the optical axis;
- pixels: x right, y down, origin at the top-left corner.

Mounting angles (degrees): ``pitch_deg`` positive looks down, ``yaw_deg`` positive looks left,
``roll_deg`` right-handed about the optical axis. The camera-to-vehicle rotation is
``Rz(yaw) @ Ry(pitch) @ Rx(roll) @ B`` where ``B`` maps camera axes to vehicle axes at zero
angles (a right-handed rotation about +y by +pitch turns +x towards -z, i.e. looks down).
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, field, replace
from enum import Enum
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from vid2sim.base.errors import FormatError, ImpossibleValueError, InconsistentInputError
from vid2sim.base.fileio import read_input_text

# Camera axes expressed in the vehicle frame at zero mounting angles (columns: cam x, y, z).
_B_VEH_FROM_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

# Default when no camera file is given: a typical windscreen dash-cam. 90 deg horizontal field
# of view is the middle of what consumer dash-cams record after their own cropping (most claim
# 120-140 deg diagonal), and 1.3 m is a passenger car's windscreen height.
DEFAULT_HFOV_DEG = 90.0
DEFAULT_HEIGHT_M = 1.3

_REQUIRED = ("image_width", "image_height", "fx", "fy", "cx", "cy")

# Physical ranges of a camera record (Camera.check):
#: largest image side [px]: 8K video is 7680 px wide.
MAX_IMAGE_SIDE_PX = 16384
#: field of view of a real lens over the image width or height [deg]: 1 deg is a long
#: telephoto, 170 deg a fisheye's rectified limit.
FOV_RANGE_DEG = (1.0, 170.0)
#: largest |coefficient| of an OpenCV distortion model: radial terms of real lenses stay
#: below ~10, the rational model's denominators below a few hundred.
MAX_DISTORTION = 1000.0
#: largest |pitch|, |yaw|, |roll| of a forward camera's mounting [deg]; dash-cams sit within a
#: few degrees of level and straight ahead.
MAX_MOUNT_ANGLE_DEG = 45.0


def _real(value: Any) -> float:
    """A YAML/JSON value as a float. Text that spells a number is one (PyYAML reads ``1e6``,
    without a sign in the exponent, as text); booleans and other types are not."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise TypeError(f"{value!r} is not a number")
    return float(value)


def _pixels(value: Any, name: str) -> int:
    """A whole number of pixels (1242 or 1242.0, not 1242.5)."""
    v = _real(value)
    if not math.isfinite(v) or v != int(v):
        raise ValueError(f"{name} {value!r} is not a whole number of pixels")
    return int(v)


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=float)


class PitchSource(str, Enum):
    """Where a camera's pitch comes from, i.e. how far it can be trusted."""

    #: a rig calibration (KITTI calibration file): the mounting is measured
    CALIBRATION = "calibration"
    #: the user's camera YAML: a dash-cam mounting, known to about a degree
    CAMERA_FILE = "camera file"
    #: no camera description: a level mounting is assumed
    DEFAULT = "default"


@dataclass(frozen=True)
class Camera:
    """A calibrated forward camera on the ego vehicle (the YAML camera record)."""

    image_width: int
    image_height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    height_m: float = DEFAULT_HEIGHT_M
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0
    roll_deg: float = 0.0
    assumptions: tuple[str, ...] = field(default=(), compare=False)
    pitch_source: PitchSource = field(default=PitchSource.CAMERA_FILE, compare=False)

    # ----------------------------------------------------------------- construction

    @classmethod
    def default_for(cls, width: int, height: int, hfov_deg: float = DEFAULT_HFOV_DEG) -> Camera:
        """A camera guessed from the image size (square pixels, centred principal point)."""
        f = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
        return cls(
            image_width=int(width), image_height=int(height), fx=f, fy=f,
            cx=(width - 1) / 2.0, cy=(height - 1) / 2.0, height_m=DEFAULT_HEIGHT_M,
            assumptions=(
                (f"no camera file: default pinhole for {width}x{height} with {hfov_deg:g} deg "
                 f"horizontal field of view, no distortion, {DEFAULT_HEIGHT_M} m above the road, "
                 "level mounting"),
            ),
            pitch_source=PitchSource.DEFAULT,
        )

    @classmethod
    def from_dict(cls, d: dict[str, Any], path: str | Path | None = None) -> Camera:
        """A camera from its record (camera YAML, a scenario's ``camera``), checked.

        Raises
        ------
        InputError
            A missing field, a value that is not a number, or any number outside its
            physical range (:meth:`check`).
        """
        if not isinstance(d, dict):
            raise FormatError(path, "camera description must be a mapping of keys to values")
        missing = [k for k in _REQUIRED if k not in d]
        if missing:
            raise FormatError(path, f"camera description lacks {', '.join(missing)}",
                              "see docs/formats.md, 'Camera file'")
        try:
            raw_dist = d.get("dist", [0.0] * 5)
            if not isinstance(raw_dist, (list, tuple)):
                raise TypeError(f"dist must be a list, got {raw_dist!r}")
            dist = tuple(_real(v) for v in raw_dist)
            cam = cls(
                image_width=_pixels(d["image_width"], "image_width"),
                image_height=_pixels(d["image_height"], "image_height"),
                fx=_real(d["fx"]), fy=_real(d["fy"]), cx=_real(d["cx"]), cy=_real(d["cy"]),
                dist=dist, height_m=_real(d.get("height_m", DEFAULT_HEIGHT_M)),
                pitch_deg=_real(d.get("pitch_deg", 0.0)), yaw_deg=_real(d.get("yaw_deg", 0.0)),
                roll_deg=_real(d.get("roll_deg", 0.0)),
            )
        except (TypeError, ValueError, OverflowError) as exc:
            raise FormatError(path, f"camera value is not a number: {exc}") from None
        if len(dist) not in (4, 5, 8, 12, 14):
            raise FormatError(path, f"dist has {len(dist)} values; OpenCV takes 4, 5, 8, 12 or 14")
        cam.check(path)
        return cam

    def check(self, path: str | Path | None = None) -> None:
        """Raise :class:`InputError` (naming ``path``) for any value outside its physical range.

        Every number finite; image size 1-:data:`MAX_IMAGE_SIDE_PX`; focal lengths giving a
        field of view of :data:`FOV_RANGE_DEG` and near-square pixels; the principal point
        inside the image; distortion coefficients of a real lens; the mounting of a forward
        camera (:data:`MAX_MOUNT_ANGLE_DEG`) 0-10 m above the road. A NaN focal length or a
        pitch of 1e6 deg would otherwise give NaN ranges or a 600 km standard deviation.
        """
        w, h = self.image_width, self.image_height
        if not (0 < w <= MAX_IMAGE_SIDE_PX and 0 < h <= MAX_IMAGE_SIDE_PX):
            raise ImpossibleValueError(path, f"image size {w}x{h} must be positive and at most "
                             f"{MAX_IMAGE_SIDE_PX} px a side")
        values = {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy,
                  "height_m": self.height_m, "pitch_deg": self.pitch_deg,
                  "yaw_deg": self.yaw_deg, "roll_deg": self.roll_deg}
        values.update({f"dist[{i}]": v for i, v in enumerate(self.dist)})
        for name, v in values.items():
            if not math.isfinite(v):
                raise ImpossibleValueError(path, f"camera {name} is {v}, not a finite number")
        if self.fx <= 0 or self.fy <= 0:
            raise ImpossibleValueError(path, "image size and focal lengths must be positive")
        lo, hi = FOV_RANGE_DEG
        for name, f, side in (("fx", self.fx, w), ("fy", self.fy, h)):
            fov = math.degrees(2.0 * math.atan(side / (2.0 * f)))
            if not lo <= fov <= hi:
                raise ImpossibleValueError(path, f"{name} {f:g} px gives a {fov:.2f} deg field of view over "
                                 f"{side} px; a camera's is {lo:g}-{hi:g} deg",
                                 "is the focal length in pixels, for this image size?")
        if not 0.5 <= self.fy / self.fx <= 2.0:
            raise ImpossibleValueError(path, f"fy / fx = {self.fy / self.fx:.3g}: pixels are not that "
                             "far from square", "check fx and fy")
        if not (0 <= self.cx <= w and 0 <= self.cy <= h):
            raise ImpossibleValueError(path, f"principal point ({self.cx:g}, {self.cy:g}) px lies outside "
                             f"the {w}x{h} image", "cx, cy are pixel coordinates of the image "
                             "centre, roughly")
        if any(abs(v) > MAX_DISTORTION for v in self.dist):
            raise ImpossibleValueError(path, f"distortion coefficients {list(self.dist)} are not a lens's "
                             f"(|k| <= {MAX_DISTORTION:g})")
        if not 0 < self.height_m < 10:
            raise ImpossibleValueError(path, f"height_m {self.height_m} is not a camera height above a road")
        for name in ("pitch_deg", "yaw_deg", "roll_deg"):
            v = getattr(self, name)
            if abs(v) > MAX_MOUNT_ANGLE_DEG:
                raise ImpossibleValueError(path, f"{name} {v:g} is not the mounting of a forward camera "
                                 f"(at most {MAX_MOUNT_ANGLE_DEG:g} deg)", "the unit is degrees")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["dist"] = list(self.dist)
        d.pop("assumptions")
        d.pop("pitch_source")
        return d

    def with_pitch(self, pitch_deg: float) -> Camera:
        return replace(self, pitch_deg=float(pitch_deg))

    def scaled_to(self, width: int, height: int) -> Camera:
        """The same camera for frames resized to ``width`` x ``height``."""
        sx, sy = width / self.image_width, height / self.image_height
        return replace(self, image_width=int(width), image_height=int(height), fx=self.fx * sx,
                       fy=self.fy * sy, cx=self.cx * sx, cy=self.cy * sy)

    # ----------------------------------------------------------------- geometry

    @property
    def K(self) -> np.ndarray:  # the usual name of the intrinsic matrix
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=float)

    @property
    def R_veh_from_cam(self) -> np.ndarray:
        return (_rot_z(math.radians(self.yaw_deg)) @ _rot_y(math.radians(self.pitch_deg))
                @ _rot_x(math.radians(self.roll_deg)) @ _B_VEH_FROM_CAM)

    @property
    def position_veh_m(self) -> np.ndarray:
        return np.array([0.0, 0.0, self.height_m])

    def vehicle_to_camera(self, points_veh_m: np.ndarray) -> np.ndarray:
        """(N, 3) vehicle-frame points [m] -> (N, 3) camera-frame points [m]."""
        p = np.asarray(points_veh_m, dtype=float).reshape(-1, 3)
        return (p - self.position_veh_m) @ self.R_veh_from_cam  # == R^T (p - t) row-wise

    def project(self, points_veh_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project vehicle-frame points to pixels.

        :return: (N, 2) pixel coordinates and an (N,) mask of points in front of the camera
            (pixels of points behind it are NaN)
        """
        p_cam = self.vehicle_to_camera(points_veh_m)
        in_front = p_cam[:, 2] > 1e-6
        uv = np.full((p_cam.shape[0], 2), np.nan)
        if in_front.any():
            pts = p_cam[in_front].reshape(-1, 1, 3)
            if any(self.dist):
                img, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), self.K,
                                           np.asarray(self.dist, dtype=float))
                uv[in_front] = img.reshape(-1, 2)
            else:  # plain pinhole: skip OpenCV's per-call overhead on the hot path
                q = pts.reshape(-1, 3)
                uv[in_front, 0] = self.fx * q[:, 0] / q[:, 2] + self.cx
                uv[in_front, 1] = self.fy * q[:, 1] / q[:, 2] + self.cy
        return uv, in_front

    def pixel_rays_veh(self, pixels_px: np.ndarray) -> np.ndarray:
        """Unit viewing rays in the vehicle frame for (N, 2) pixels (distortion removed)."""
        px = np.asarray(pixels_px, dtype=float).reshape(-1, 1, 2)
        if any(self.dist):
            norm = cv2.undistortPoints(px, self.K, np.asarray(self.dist, dtype=float)).reshape(-1, 2)
        else:
            norm = np.column_stack(((px[:, 0, 0] - self.cx) / self.fx,
                                    (px[:, 0, 1] - self.cy) / self.fy))
        rays_cam = np.column_stack((norm, np.ones(len(norm))))
        rays = rays_cam @ self.R_veh_from_cam.T
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def pixel_to_ground(self, pixels_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Back-project pixels onto the flat road plane z = 0.

        :return: (N, 3) vehicle-frame points [m] and an (N,) mask of pixels below the
            horizon (points of other pixels are NaN)
        """
        rays = self.pixel_rays_veh(pixels_px)
        down = rays[:, 2] < -1e-9
        out = np.full((rays.shape[0], 3), np.nan)
        s = -self.height_m / rays[down, 2]
        out[down] = self.position_veh_m + s[:, None] * rays[down]
        return out, down

    def horizon_y_px(self, u_px: float | None = None) -> float:
        """Image row of the horizon (vanishing line of the road plane) at column ``u_px``.

        Exact for zero distortion; with distortion it is the row at the principal point column.
        """
        u = self.cx if u_px is None else float(u_px)
        # The horizon is the image of directions with zero vehicle z: n . ray_cam = 0 where n is
        # the vehicle up axis in camera coordinates.
        n = self.R_veh_from_cam.T @ np.array([0.0, 0.0, 1.0])
        xn = (u - self.cx) / self.fx
        # n0*xn + n1*yn + n2 = 0
        if abs(n[1]) < 1e-12:
            return float("nan")
        yn = -(n[0] * xn + n[2]) / n[1]
        return float(yn * self.fy + self.cy)

    def box_corners_veh(self, center_veh_m: np.ndarray, length_m: float, width_m: float,
                        height_m: float, yaw_rad: float = 0.0) -> np.ndarray:
        """(8, 3) corners of a box standing on the road, centre of its footprint at
        ``center_veh_m`` (x, y[, z]), yawed ``yaw_rad`` relative to the vehicle x axis."""
        c = np.asarray(center_veh_m, dtype=float)
        z0 = c[2] if c.size > 2 else 0.0
        dx, dy = length_m / 2.0, width_m / 2.0
        local = np.array([[sx * dx, sy * dy] for sx in (-1, 1) for sy in (-1, 1)])
        cs, sn = math.cos(yaw_rad), math.sin(yaw_rad)
        xy = local @ np.array([[cs, sn], [-sn, cs]]) + c[:2]
        bottom = np.column_stack((xy, np.full(4, z0)))
        top = np.column_stack((xy, np.full(4, z0 + height_m)))
        return np.vstack((bottom, top))

    def project_box(self, center_veh_m: np.ndarray, length_m: float, width_m: float,
                    height_m: float, yaw_rad: float = 0.0, clip: bool = True
                    ) -> tuple[float, float, float, float] | None:
        """Pixel box (x1, y1, x2, y2) enclosing a projected 3D box; None if any corner is
        behind the camera or the box lies wholly outside the image."""
        corners = self.box_corners_veh(center_veh_m, length_m, width_m, height_m, yaw_rad)
        uv, ok = self.project(corners)
        if not ok.all():
            return None
        x1, y1 = uv.min(axis=0)
        x2, y2 = uv.max(axis=0)
        if x2 < 0 or y2 < 0 or x1 > self.image_width - 1 or y1 > self.image_height - 1:
            return None
        if clip:
            x1, x2 = np.clip([x1, x2], 0, self.image_width - 1)
            y1, y2 = np.clip([y1, y2], 0, self.image_height - 1)
        return float(x1), float(y1), float(x2), float(y2)


# Frame sizes within this relative difference of the calibrated size are a crop (KITTI's
# rectified images differ by up to ~1.5% between recording days; codecs pad or drop a few
# rows): the intrinsics stay. Larger differences must be a resize of the calibrated video.
CROP_TOLERANCE = 0.05
# A resize keeps the aspect ratio; beyond this relative difference the camera file belongs
# to another video.
RESIZE_ASPECT_TOLERANCE = 0.01


def fit_camera_to_frames(camera: Camera, width_px: int, height_px: int,
                         path: str | Path | None = None) -> tuple[Camera, str | None]:
    """The camera for frames of ``width_px`` x ``height_px``, and a note if it changed.

    Same size: unchanged. Within :data:`CROP_TOLERANCE`: a crop, so the intrinsics are kept
    and only the image size changes. Otherwise, with the same aspect ratio, a resize: the
    intrinsics are scaled. Anything else is another camera's file.

    Raises
    ------
    InputError
        If the frames are neither a crop nor a resize of the calibrated image (``path`` names
        the camera file in the message).
    """
    w0, h0 = camera.image_width, camera.image_height
    if (w0, h0) == (width_px, height_px):
        return camera, None
    if abs(width_px / w0 - 1) <= CROP_TOLERANCE and abs(height_px / h0 - 1) <= CROP_TOLERANCE:
        return (replace(camera, image_width=int(width_px), image_height=int(height_px)),
                (f"camera is for {w0}x{h0} px, frames are {width_px}x{height_px} px: taken "
                 "as a crop, intrinsics kept"))
    aspect0, aspect = w0 / h0, width_px / height_px
    if abs(aspect / aspect0 - 1) <= RESIZE_ASPECT_TOLERANCE:
        return (camera.scaled_to(width_px, height_px),
                (f"camera is for {w0}x{h0} px, frames are {width_px}x{height_px} px: taken "
                 "as a resize, intrinsics scaled"))
    raise InconsistentInputError(path, f"camera is for {w0}x{h0} images but the frames are "
                     f"{width_px}x{height_px}", "give the camera file of this video, or none "
                     "for a default camera")


# --------------------------------------------------------------------------- readers


def load_camera(path: str | Path) -> Camera:
    """Read a camera YAML file (the project's format) or a KITTI calibration file."""
    path = Path(path)
    text = read_input_text(path, max_bytes=MAX_CAMERA_FILE_BYTES)
    if re.search(r"^(P_rect_0\d|P\d)\s*:", text, flags=re.MULTILINE):
        return _kitti_camera(text, path)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise FormatError(path, f"not valid YAML: {(str(exc).splitlines() or ['?'])[0]}") from None
    except RecursionError:
        raise FormatError(path, "YAML nested too deeply to read") from None
    return Camera.from_dict(data, path)


#: Largest camera file [bytes]: a camera record is a few hundred bytes, a KITTI calibration
#: a few kB.
MAX_CAMERA_FILE_BYTES = 1024 * 1024

# KITTI's camera rig: cameras are 1.65 m above the road (Geiger et al., IJRR 2013).
KITTI_CAMERA_HEIGHT_M = 1.65


def parse_kitti_calib(text: str) -> dict[str, np.ndarray]:
    """``KEY: numbers`` lines of a KITTI calibration file -> {KEY: array}; lines without
    numbers (``calib_time: ...``) are skipped."""
    values: dict[str, np.ndarray] = {}
    for line in text.splitlines():
        if ":" not in line:
            continue
        key, _, rest = line.partition(":")
        try:
            values[key.strip()] = np.array([float(v) for v in rest.split()])
        except ValueError:
            continue
    return values


def _kitti_camera(text: str, path: Path, cam: int = 2) -> Camera:
    """Camera from a KITTI ``calib_cam_to_cam.txt`` (``P_rect_0N``, ``S_rect_0N``) or a
    tracking/object ``calib/SSSS.txt`` (``P0..P3``); camera ``cam`` (default 2, the left
    colour camera), rectified, so without distortion."""
    values = parse_kitti_calib(text)
    proj = values.get(f"P_rect_{cam:02d}")
    if proj is None:
        proj = values.get(f"P{cam}")
    if proj is None or proj.size != 12:
        raise FormatError(path, f"KITTI calibration lacks a 3x4 projection for camera {cam}")
    size = values.get(f"S_rect_{cam:02d}")
    if size is not None and size.size != 2:
        raise FormatError(path, f"S_rect_{cam:02d} must be two numbers (width height)")
    try:
        width, height = ((_pixels(float(size[0]), "width"), _pixels(float(size[1]), "height"))
                         if size is not None else (1242, 375))
    except (ValueError, OverflowError) as exc:
        raise FormatError(path, f"S_rect_{cam:02d}: {exc}") from None
    p = proj.reshape(3, 4)
    assumptions = [f"KITTI calibration: camera {cam} rectified, {KITTI_CAMERA_HEIGHT_M} m high"]
    if size is None:
        assumptions.append("image size not in the calibration: assumed 1242x375")
    camera = Camera(image_width=width, image_height=height, fx=float(p[0, 0]), fy=float(p[1, 1]),
                    cx=float(p[0, 2]), cy=float(p[1, 2]), height_m=KITTI_CAMERA_HEIGHT_M,
                    assumptions=tuple(assumptions), pitch_source=PitchSource.CALIBRATION)
    camera.check(path)
    return camera
